"""The human body: SMPL-24 forward kinematics without and with the SMPL model file, rotation conversions,
kinematics helpers, resampling between frame rates, temporal filters and per-channel statistics."""
