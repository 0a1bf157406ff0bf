"""Pretrained folders (``config.json``, ``model.safetensors``, ``README.md``) and the Hub: the mixin every
network inherits (:mod:`.mixin`: ``save_pretrained`` / ``from_pretrained`` / ``push_to_hub``), the JSON codec
of ``config.json`` (:mod:`.codec`), the checks a folder passes before anything is allocated (:mod:`.checks`,
with the size bounds the commands' parsers share, :mod:`.size_bounds`), the model card (:mod:`.card`) and the
Hub client (:mod:`.hub`). Loading unpickles nothing."""
