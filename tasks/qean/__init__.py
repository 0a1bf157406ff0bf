"""QEAN: Quaternion-Enhanced Attention Network for music-to-dance generation ([QEAN])."""
