"""The pose model's angle head (kind ``"angle_head"``): the contact's in-plane axis from one reading. Its network
(:mod:`.model`), training (:mod:`.train`), export into a pose model's ONNX file (:mod:`.export`) and what ``train``
and ``export`` do with it (:mod:`.verbs`)."""
