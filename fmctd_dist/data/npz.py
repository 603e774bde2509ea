"""Byte-deterministic .npz files (numpy's savez stamps the wall clock into the zip headers), and
a checked loader: every array a reader needs must be there with the dtype and shape it expects."""

from __future__ import annotations

import io
import zipfile
from pathlib import Path

import numpy as np

from fmctd_dist.errors import DatasetError

_EPOCH = (1980, 1, 1, 0, 0, 0)


def save_npz(path: Path, arrays: dict[str, np.ndarray]) -> None:
    """Write ``arrays`` as an uncompressed .npz with fixed timestamps and key order."""
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_STORED) as zf:
        for key in sorted(arrays):
            buf = io.BytesIO()
            np.lib.format.write_array(buf, np.ascontiguousarray(arrays[key]), allow_pickle=False)
            info = zipfile.ZipInfo(f"{key}.npy", date_time=_EPOCH)
            info.external_attr = 0o644 << 16
            zf.writestr(info, buf.getvalue())


def load_npz(path: Path, expect: dict[str, tuple[np.dtype | type, tuple[int | None, ...]]],
             fix: str) -> dict[str, np.ndarray]:
    """The arrays ``expect`` names, each checked: ``{key: (dtype, shape)}`` (None in a shape = any size).

    No pickles (``allow_pickle=False``: an object array is refused, never unpickled). A missing
    key, another dtype or another shape is one :class:`DatasetError` naming the file, the key,
    what it holds and what was expected, followed by ``fix``.
    """
    try:
        with np.load(path, allow_pickle=False) as z:
            missing = [k for k in expect if k not in z.files]
            if missing:
                raise DatasetError(f"{path} has no array {missing[0]!r} (it holds {sorted(z.files)}); {fix}")
            arrays = {k: z[k] for k in expect}
    except DatasetError:
        raise
    except (ValueError, OSError, EOFError, zipfile.BadZipFile) as e:  # object arrays, truncated or not a zip
        why = str(e).strip().splitlines()
        raise DatasetError(f"{path} is malformed ({type(e).__name__}: {why[0][:200] if why else ''}); {fix}") from None
    for key, (dtype, shape) in expect.items():
        a = arrays[key]
        if a.dtype != np.dtype(dtype):
            raise DatasetError(f"{path}: {key} has dtype {a.dtype} but must be {np.dtype(dtype)}; {fix}")
        if a.ndim != len(shape) or any(w is not None and h != w for h, w in zip(a.shape, shape)):
            want = "[" + ", ".join("*" if w is None else str(w) for w in shape) + "]"
            raise DatasetError(f"{path}: {key} has shape {list(a.shape)} but must be {want}; {fix}")
    return arrays
