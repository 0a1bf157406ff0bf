"""Skeleton-based human action recognition ([NTU RGB+D] 60/120, [Kinetics]; [EgoMusic] supp. 8.1)."""
