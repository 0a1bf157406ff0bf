"""Text-to-motion on [HumanML3D] ([EgoMusic] supp. Sec. 8.2).

``humanml3d`` (files, captions, splits), ``features`` (the 263-d representation, ``recover_from_ric``),
``convert_cli`` (``sm convert``), ``metrics`` / ``evaluator`` / ``glove`` (the T2M evaluation networks and
scores), ``evaluation`` / ``evaluation_report`` (the protocol's driver run by ``sm test`` and its table),
``text_encoder`` (frozen CLIP / MiniLM), ``model`` (the Skeleton Mamba denoiser), ``baseline`` (an
MDM-style transformer denoiser for comparisons), ``module`` / ``data`` (Lightning), ``synthetic`` (a
SYNTHETIC captioned demo set), ``demo`` (the demo's generate-after-training callback), ``generate_cli``
(``sm generate``).
"""
