"""The toolkit's ``sm`` commands, each a parser (``*_args.py``, torch-free so ``--help`` is fast) and a
runner (``*_cli.py`` or the command's name): ``analyze-music``, ``evaluate-dance``, ``export``, ``render``,
``retarget``, ``view``; and what every command's parser shares (:mod:`.cli_options`)."""
