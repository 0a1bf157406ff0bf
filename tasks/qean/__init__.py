"""QEAN: Quaternion-Enhanced Attention Network for music-to-dance generation (seed 003)."""
