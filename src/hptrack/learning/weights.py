"""Reading model and checkpoint files as data only: tensors and plain containers through
torch's weights-only unpickler, never pickled objects (a pickle can run any code when it is
loaded, so a model file from somebody else must not be unpickled).

Every failure is a `ValueError` of one line that names the file and says what it is
when that is recognisable (a stable-baselines3 zip, a torch file).
"""

from __future__ import annotations

import io
import warnings
import zipfile
from pathlib import Path
from typing import Any

import torch

SB3_POLICY_MEMBER = "policy.pth"
"""The member of a stable-baselines3 zip that holds the policy's tensors."""
MAX_MEMBER_BYTES = 2**28
"""Largest zip member read (256 MiB uncompressed; a policy is well under 1 MiB)."""


def describe(path: str | Path) -> str:
    """What ``path`` is, as far as its container tells: ``"a stable-baselines3 model"``, ``"a
    torch file"``, ``"a zip file"``, ``"not a torch or stable-baselines3 file"`` or ``"no such
    file"``."""
    if not Path(path).is_file():
        return "no such file"
    if not zipfile.is_zipfile(path):
        return "not a torch or stable-baselines3 file"
    with zipfile.ZipFile(path) as archive:
        names = archive.namelist()
    if SB3_POLICY_MEMBER in names:
        return "a stable-baselines3 model"
    if any(name.endswith("/data.pkl") for name in names):
        return "a torch file"
    return "a zip file"


def load_weights(source: str | Path | bytes, label: str) -> Any:
    """``torch.load(source, weights_only=True)`` on the CPU, torch's warnings silenced.

    Raises:
        ValueError: ``label`` (e.g. ``"ADFQ model runs/x/best.pt"``) and why it cannot be read:
            a pickle of objects other than tensors and plain containers is refused.
    """
    file = io.BytesIO(source) if isinstance(source, bytes) else source
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return torch.load(file, map_location="cpu", weights_only=True)
    except Exception as err:  # any parse failure of a foreign file is that file's fault
        if "Weights only load failed" in str(err):
            raise ValueError(
                f"{label}: refused: not a file of tensors only (a model may not hold pickled "
                "objects, which could run code when loaded)"
            ) from None
        what = "damaged" if isinstance(source, bytes) else describe(source)
        raise ValueError(f"{label}: cannot be read as a torch file ({what})") from None


def read_zip_member(path: str | Path, member: str, label: str) -> bytes:
    """The bytes of ``member`` in the zip ``path``.

    Raises:
        ValueError: ``path`` is not a zip or has no ``member`` (``label`` names it).
    """
    try:
        with zipfile.ZipFile(path) as archive:
            size = archive.getinfo(member).file_size
            if size > MAX_MEMBER_BYTES:
                raise ValueError(
                    f"{label}: {member} is {size:,} bytes uncompressed, more than a model's "
                    f"{MAX_MEMBER_BYTES:,}"
                )
            return archive.read(member)
    except zipfile.BadZipFile:
        raise ValueError(f"{label}: not a zip file ({describe(path)})") from None
    except KeyError:
        raise ValueError(f"{label}: no {member} in it ({describe(path)})") from None
