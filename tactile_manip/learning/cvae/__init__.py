"""The SuperMag conditional VAE (kind ``"cvae"``): a depth image from one reading. Its network (:mod:`.model`),
the training data as tensors (:mod:`.data`), training (:mod:`.train`), ONNX export (:mod:`.export`), a torch-eager
reference (:mod:`.eager`) and what ``train`` and ``export`` do with it (:mod:`.verbs`)."""
