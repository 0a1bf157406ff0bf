"""EgoMusic dance estimation: egocentric video + music -> full-body SMPL-24 dance ([EgoMusic]).

``builder/`` holds the EgoAIST++ dataset builder (``sm make-ego``, [EgoMusic] supp. Sec. 5): it splits
dance motions into 5 s windows, places each in a 3D scene (feet on the floor, penetration score
``S_p <= 2``), and renders the egocentric RGB + depth frames from a camera between the eyes. Its on-disk
layout is documented in :mod:`skeleton_mamba.tasks.egodance.builder.layout`.
"""
