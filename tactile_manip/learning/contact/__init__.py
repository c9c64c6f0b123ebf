"""The contact network (kind ``"contact"``): contact targets with a sigma each from a window of readings. Its
network (:mod:`.model`), training (:mod:`.train`; labels from a few labelled presses: :mod:`.fewlabel`, their
places refitted by :mod:`.field_inverse`), ONNX export (:mod:`.export`) and what ``train`` and ``export`` do
with it (:mod:`.verbs`)."""
