"""The motion and music toolkit the tasks share, in rooms by job.

- :mod:`.io`: reading what the outside world hands us safely (pickles, ``.npy`` / ``.npz`` values,
  range-checked options) and writing only what we may (output folders, the feature cache);
- :mod:`.formats`: one module per motion file format (BVH, NTU skeletons, AIST++, HumanML3D features, glTF,
  our ``.npz``, mp4) and the reader that picks one (:mod:`.formats.motion_reader`);
- :mod:`.body`: the body: SMPL kinematics and model, rotations, resampling, filters, statistics;
- :mod:`.music`: audio decoding, beats and music features, pretrained audio encoders;
- :mod:`.metrics`: the dance and motion metrics and the evaluation protocols;
- :mod:`.render`: videos of skeletons and meshes, and the browser viewer;
- :mod:`.retarget`: motion onto a user's character (glTF, VRM, BVH rigs);
- :mod:`.synthetic`: procedural dances, actions and music for demos and tests;
- :mod:`.commands`: the toolkit's ``sm`` commands (their parsers and runners) and the options every command
  shares.

The backbone's errors (:mod:`skeleton_mamba.errors`), bounded reader and atomic writer sit below all of these.
"""
