"""Runs stored under a key: a pickle that is read back only while its key matches.

The key of a run is the SHA-256 of what names it (study, settings, seed), of the package's
source and of the input files it was computed from, so a stored result is reused only by
the code and the data that produced it. Used by the papers' studies
(:class:`mascore.registry.Study`) and by the comparison's sweep (:func:`mascore.compare.run`).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

__all__ = ["read_run", "run_digest", "source_digest", "write_run"]


def source_digest() -> str:
    """SHA-256 of the package's source: every ``.py`` file of ``mascore``, by path and content.

    Returns
    -------
    str
        64 hexadecimal digits; it changes when any module of the package changes.

    Examples
    --------
    >>> from mascore._runstore import source_digest
    >>> len(source_digest())
    64
    """
    import hashlib

    root = Path(__file__).resolve().parent
    digest = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        digest.update(path.relative_to(root).as_posix().encode() + b"\0" + path.read_bytes() + b"\0")
    return digest.hexdigest()


def run_digest(identity: tuple, files: Sequence[Path] = ()) -> str:
    """The key of a stored run: SHA-256 of `identity`'s repr, the package's source and the bytes of `files`.

    Parameters
    ----------
    identity : tuple
        What names the run (study, settings, seed, ...); its ``repr`` must be deterministic.
    files : sequence of pathlib.Path
        Input files the run was computed from (the comparison's sweep table); each must exist.

    Returns
    -------
    str
        64 hexadecimal digits: equal keys, the same result byte for byte.
    """
    import hashlib

    digest = hashlib.sha256(repr(identity).encode())
    digest.update(source_digest().encode())
    for path in files:
        digest.update(hashlib.sha256(Path(path).read_bytes()).hexdigest().encode())
    return digest.hexdigest()


def write_run(path: Path, key: str, result: Any, pickled: bytes | None = None) -> Path | None:
    """Pickle `result` to `path` after its `key` (read first, so that a stale file is never unpickled).

    The file is written beside `path` and then renamed onto it, so that a reader (another
    notebook's kernel) sees the old file or the new one, never half of one.

    Parameters
    ----------
    path : pathlib.Path
        The file (its folder is created).
    key : str
        The run's key (:func:`run_digest`, :meth:`mascore.registry.Study.run_key`).
    result : object
        What to store.
    pickled : bytes, optional
        ``pickle.dumps(result, protocol=4)`` made where `result` was computed, written as it is.

    Returns
    -------
    pathlib.Path or None
        `path`; None if `result` cannot be pickled (a class defined inside a function): nothing is written.
    """
    import os
    import pickle
    import uuid

    try:
        data = pickle.dumps(result, protocol=4) if pickled is None else pickled
    except (pickle.PicklingError, AttributeError, TypeError):  # local classes cannot be pickled
        return None
    path.parent.mkdir(parents=True, exist_ok=True)
    scratch = path.with_name(f".{path.name}.{uuid.uuid4().hex}.part")  # one per writer
    try:
        with scratch.open("xb") as f:
            pickle.dump(key, f, protocol=4)
            f.write(data)
        os.replace(scratch, path)
    except BaseException:
        scratch.unlink(missing_ok=True)
        raise
    return path


def read_run(path: Path, key: str) -> tuple[bool, Any]:
    """The result :func:`write_run` stored at `path` under `key`: ``(True, result)``, else ``(False, None)``.

    Only the key is read from a file stored under another key (or a missing file). Read only
    files you wrote yourself (a pickle).

    Parameters
    ----------
    path : pathlib.Path
        The file.
    key : str
        The key the result must have been stored under.

    Returns
    -------
    (bool, object)
        Whether a result was found, and the result (None when not).
    """
    import pickle

    if not path.is_file():
        return False, None
    with path.open("rb") as f:
        if pickle.load(f) != key:
            return False, None
        return True, pickle.load(f)
