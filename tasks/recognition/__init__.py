"""Skeleton-based human action recognition (NTU RGB+D 60/120, Kinetics-skeleton; seed 000 section 8.1)."""
