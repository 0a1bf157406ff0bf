"""The EgoAIST++ dataset builder (``sm make-ego``), [EgoMusic] supp. Sec. 5.

One module per concept: :mod:`.scene` (loading, up axis, floor), :mod:`.procedural_scene` (furnished
rooms), :mod:`.placement` (random floor location and heading, feet on the floor), :mod:`.penetration`
(capsule body or SMPL mesh, score ``S_p``), :mod:`.body_mesh` (the posed SMPL mesh of ``--smpl-model``),
:mod:`.camera` (eye camera), :mod:`.ray_caster` (embree first hits), :mod:`.raycast` (RGB + depth renderer),
:mod:`.layout` (the documented on-disk layout, read and write), :mod:`.build` (resumable multi-process
driver) and :mod:`.make_ego_cli` (``sm make-ego``).
"""
