"""Streaming: live music-to-dance and online action recognition on a causal Skeleton Mamba."""
