"""Music: audio decoding with bounded reads (:mod:`.audio_io`), the beats and features the models and
protocols use (:mod:`.features`, :mod:`.protocol_music`), window-by-window analysis of long tracks,
pretrained audio encoders and the numba cache librosa compiles into."""
