"""Text-to-motion on HumanML3D (seed 000 section 8.2).

``humanml3d`` (files, captions, splits), ``features`` (the 263-d representation, ``recover_from_ric``),
``convert_cli`` (``sm convert``), ``metrics`` / ``evaluator`` / ``glove`` (the T2M evaluation protocol),
``text_encoder`` (frozen CLIP / MiniLM), ``model`` (the Skeleton Mamba denoiser), ``module`` / ``data``
(Lightning), ``synthetic`` (a SYNTHETIC captioned demo set), ``generate_cli`` (``sm generate``).
"""
