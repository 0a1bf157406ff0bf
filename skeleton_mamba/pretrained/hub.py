"""The Hugging Face Hub side of pretrained folders: a Hub id resolved to a local folder through the Hugging
Face cache, and a folder uploaded as a Hub model repository.

Only the three files of a folder (:data:`~skeleton_mamba.pretrained.codec.FOLDER_FILES`) are downloaded or
uploaded. The client's functions are looked up on the ``huggingface_hub`` module at each call, so a test can
replace them (``huggingface_hub.HfApi`` by a recorder of the calls).
"""

from __future__ import annotations

import os
import re
from pathlib import Path
from typing import Any

import huggingface_hub
from huggingface_hub.utils import HfHubHTTPError, HFValidationError, LocalEntryNotFoundError

from skeleton_mamba.pretrained.codec import (
    CONFIG_NAME,
    FOLDER_FILES,
    WEIGHTS_NAME,
    PretrainedError,
    read_pretrained_config,
)

__all__ = ["push_folder_to_hub", "resolve_pretrained"]

_HUB_ID = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*/[A-Za-z0-9][A-Za-z0-9_.-]*$")


def resolve_pretrained(
    source: str | os.PathLike[str],
    *,
    revision: str | None = None,
    cache_dir: str | os.PathLike[str] | None = None,
    local_files_only: bool = False,
    token: str | bool | None = None,
) -> Path:
    """The local folder of ``source``: a folder as given, or a Hub id (``org/name``) through the Hugging Face
    cache (downloaded once; ``HF_HUB_OFFLINE=1`` or ``local_files_only`` reads the cache only).

    Raises:
        PretrainedError: neither a folder nor a Hub id, or the Hub id cannot be resolved.

    Examples:
        >>> import tempfile
        >>> folder = tempfile.mkdtemp()
        >>> resolve_pretrained(folder) == Path(folder)  # a local folder, as given
        True
        >>> resolve_pretrained("no/such/folder")  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        skeleton_mamba.pretrained.codec.PretrainedError: no/such/folder: no such folder, and not a Hub id...
    """
    text = os.fspath(source)
    path = Path(text).expanduser()
    if path.is_dir():
        return path
    if path.exists():
        raise PretrainedError(
            f"{text}: is a file; a from_pretrained folder ({CONFIG_NAME} + {WEIGHTS_NAME}) "
            "or a Hub id is expected"
        )
    if not _HUB_ID.match(text) or text.startswith((".", "~")):
        raise PretrainedError(f"{text}: no such folder, and not a Hub id (org/name)")
    try:
        folder = huggingface_hub.snapshot_download(
            text,
            revision=revision,
            cache_dir=cache_dir,
            local_files_only=local_files_only,
            token=token,
            allow_patterns=list(FOLDER_FILES),
            library_name="skeleton-mamba",
        )
    except (LocalEntryNotFoundError, HFValidationError, HfHubHTTPError, OSError) as err:
        first = str(err).strip().splitlines()
        raise PretrainedError(
            f"{text}: no such folder, and the Hub id does not resolve ({type(err).__name__}: "
            f"{first[0] if first else ''})"
        ) from err
    return Path(folder)


def push_folder_to_hub(
    folder: str | os.PathLike[str],
    repo_id: str,
    *,
    private: bool | None = None,
    token: str | None = None,
    revision: str | None = None,
    commit_message: str = "Upload Skeleton Mamba network",
) -> Any:
    """Create the Hub model repository ``repo_id`` (when missing) and upload ``folder``'s three files."""
    read_pretrained_config(folder)
    api = huggingface_hub.HfApi(token=token)
    api.create_repo(repo_id, private=private, exist_ok=True, repo_type="model")
    return api.upload_folder(
        repo_id=repo_id,
        folder_path=os.fspath(folder),
        revision=revision,
        commit_message=commit_message,
        allow_patterns=list(FOLDER_FILES),
        repo_type="model",
    )
