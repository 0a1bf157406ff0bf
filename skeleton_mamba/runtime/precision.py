"""The inference precisions of the commands (``sm dance``, ``sm stream``) by name, with their help.

Torch-free, so that a command's ``--help`` lists them without importing torch;
:func:`skeleton_mamba.ssd.precision.inference_precision` runs them.
"""

PRECISIONS = ("fp32", "bf16")
PRECISION_HELP = (
    "fp32 (default) or bf16: the network under bfloat16 autocast (weights fp32; projections, convolutions "
    "and attention in bf16; the SSD's decays, cumulative sums and states in fp32); not with --compile."
)
