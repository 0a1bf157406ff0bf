"""Safe input and output: pickles unpickled without code (:mod:`.safe_pickle`), checks on values read from
files (:mod:`.value_checks`), range-checked command-line values (:mod:`.option_types`), output folders that
replace only what ``sm`` wrote (:mod:`.output_folder`) and the on-disk feature cache (:mod:`.cache`). A new
guard on what enters or leaves the program goes here."""
