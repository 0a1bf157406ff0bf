"""Training machinery shared by every task: the ``sm`` command line and its error policy, LightningCLI
and recipe resolution, checkpoints, run folders, run guards, the progress bar, the Lightning adapter, the
module and data-module bases, the backbone configuration and the one Gaussian diffusion (``diffusion/``).

Layer: imports the backbone (``skeleton_mamba``) and the toolkit (``skeleton_mamba.tasks.motion``), never a
task; tasks import it. Importing this package imports nothing (``sm --help`` stays light).
"""
