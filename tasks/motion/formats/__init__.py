"""Motion file formats, one module each: BVH, NTU RGB+D skeletons, AIST++ (with its splits), HumanML3D
features, the FACT vector, glTF (written and read), our motion ``.npz``, length units and mp4 encoding;
:mod:`.motion_reader` reads any of them by its suffix and :mod:`.export` writes a motion in all of them. A
new file format goes here."""
