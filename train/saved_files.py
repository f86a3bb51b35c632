"""The files of a saved policy checked before they are loaded: the SB3 model archive and its
``VecNormalize`` statistics. A corrupted or truncated file, or missing statistics, is refused
with one line naming the file (``ValueError``), so a command refuses it before any work instead
of failing with a traceback from inside SB3 or pickle.

An SB3 model (``BaseAlgorithm.save``) is a zip archive holding ``data`` (the JSON of the
algorithm's attributes) and ``policy.pth`` (the network's weights); the statistics are a pickled
``stable_baselines3.common.vec_env.VecNormalize`` (``VecNormalize.save``).
"""

from __future__ import annotations

import pickle
import zipfile
from pathlib import Path

__all__ = ["check_model_file", "check_vecnormalize_file", "check_checkpoint", "vecnormalize_path"]

#: the entries every SB3 model archive holds
MODEL_ENTRIES = ("data", "policy.pth")


def vecnormalize_path(model_path: Path) -> Path | None:
    """The VecNormalize statistics saved beside ``model_path`` (None if there are none):
    ``model.zip`` -> ``vecnormalize.pkl``, ``best_model.zip`` -> ``best_vecnormalize.pkl``, a
    checkpoint ``model_<N>_steps.zip`` -> ``model_vecnormalize_<N>_steps.pkl`` (SB3's
    ``CheckpointCallback`` names)."""
    model_path = Path(model_path)
    stem = model_path.name.removesuffix(".zip")
    names = [stem.replace("model", "vecnormalize", 1) + ".pkl"]
    if stem.startswith("model_") and stem.endswith("_steps"):
        names.insert(0, "model_vecnormalize_" + stem.removeprefix("model_") + ".pkl")
    for name in names:
        if (model_path.parent / name).is_file():
            return model_path.parent / name
    return None


def check_model_file(path: str | Path) -> Path:
    """``path`` as a ``Path`` if it is a readable SB3 model archive whose every entry passes its
    CRC (a truncated or corrupted file does not); ``ValueError`` naming it otherwise."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: no model file there")
    try:
        with zipfile.ZipFile(path) as archive:
            names = set(archive.namelist())
            missing = [n for n in MODEL_ENTRIES if n not in names]
            if missing:
                raise ValueError(f"{path}: not a saved SB3 model (no {', '.join(missing)} in the archive)")
            bad = archive.testzip()
    except (zipfile.BadZipFile, OSError, EOFError) as exc:
        raise ValueError(f"{path}: not a readable model archive, corrupted or truncated ({exc})") from None
    if bad is not None:
        raise ValueError(f"{path}: corrupted model archive (entry {bad} fails its CRC check)")
    return path


def check_vecnormalize_file(path: str | Path | None, model: str | Path) -> Path:
    """``path`` as a ``Path`` if it holds the pickled ``VecNormalize`` statistics of ``model``
    (``None``: none were found beside it); ``ValueError`` naming both otherwise. Unpickling runs
    the file's code, as ``VecNormalize.load`` would: it is the user's own run folder."""
    from stable_baselines3.common.vec_env import VecNormalize

    if path is None:
        raise ValueError(f"{model}: no VecNormalize statistics beside it (the policy was trained on normalised "
                         "observations; without them it would act on raw ones)")
    path = Path(path)
    try:
        with open(path, "rb") as fh:
            stats = pickle.load(fh)
    except Exception as exc:  # noqa: BLE001 (any failure to unpickle is the file's: say it in one line)
        raise ValueError(f"{path}: unreadable VecNormalize statistics of {Path(model).name} "
                         f"({type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''})") from None
    if not isinstance(stats, VecNormalize):
        raise ValueError(f"{path}: holds a {type(stats).__name__}, not the VecNormalize statistics of "
                         f"{Path(model).name}")
    return path


def check_checkpoint(ckpt: str | Path) -> None:
    """``azimut train --resume``'s checkpoint and the VecNormalize statistics beside it, read
    before any work (``ValueError``, one line, starting ``--resume:``: a corrupted or truncated
    checkpoint, or missing or unreadable statistics, raised a traceback from inside SB3 after the
    env was built)."""
    try:
        check_model_file(ckpt)
        check_vecnormalize_file(vecnormalize_path(Path(ckpt)), ckpt)
    except ValueError as exc:
        raise ValueError(f"--resume: {exc}") from None
