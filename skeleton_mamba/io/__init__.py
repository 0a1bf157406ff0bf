"""The backbone's file handling, standard library only, which every layer above uses: the one bounded reader
of JSON and YAML text (:mod:`.bounded_read`) and the one atomic writer (:mod:`.atomic`)."""
