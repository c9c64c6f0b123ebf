"""Training and export of the package's models, one folder each: the SuperMag CVAE (:mod:`.cvae`), the pose
model's angle head (:mod:`.angle_head`) and the contact network (:mod:`.contact`), with the table of model kinds
the ``train`` and ``export`` commands dispatch on (:mod:`.kinds`). The only package that imports torch.

The modules that moved into the folders (``learning.train``, ``learning.contact_model``, ...) stay importable
under their old names.
"""
