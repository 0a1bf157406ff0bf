"""Seeing motion: skeleton videos (:mod:`.skeleton`), a character's skinned mesh (:mod:`.character`,
:mod:`.character_mesh`, :mod:`.mesh`) and the self-contained browser viewer (:mod:`.view` with the three.js
files of ``viewer/``)."""
