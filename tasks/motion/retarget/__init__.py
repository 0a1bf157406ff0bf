"""Retargeting: any motion onto a user's humanoid rig (glTF, VRM, BVH): the rig and its bone map
(:mod:`.rig`), the transfer of rotations, root path and floor contact (:mod:`.transfer`), the plan a browser
page applies live (:mod:`.live`) and the ``--rig`` option of the commands (:mod:`.rig_output`)."""
