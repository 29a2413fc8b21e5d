"""Where a SigMF recording's files are: a metadata and a data file side by side, or members of a
SigMF archive (``NAME.sigmf``: an uncompressed tar holding ``NAME/NAME.sigmf-meta`` and
``NAME/NAME.sigmf-data``, as the sigmf package's ``archive()`` writes it; sigmf.org, "SigMF
Archive Format").

Either way a recording is named by its base name (``rec``, or ``rec.rx1`` for an export's
auxiliary channel) and gives its metadata text and its samples, memory-mapped (an archive's
data member in place: the tar stores it uncompressed, at a known offset), never converted.
"""

from __future__ import annotations

import tarfile
from pathlib import Path

import numpy as np

ARCHIVE = ".sigmf"
COMPRESSED_ARCHIVES = (".sigmf.gz", ".sigmf.xz", ".sigmf.zip")
META, DATA = ".sigmf-meta", ".sigmf-data"
SUFFIXES = (META, DATA, *COMPRESSED_ARCHIVES, ARCHIVE)  # the names a SigMF recording goes by
MAX_META_BYTES = 1 << 30  # metadata (a file, or an archive's members in all) rtsar reads


class SideBySide:
    """``NAME.sigmf-meta`` and ``NAME.sigmf-data`` in one folder."""

    def __init__(self, folder: Path):
        self.folder = folder

    def describe(self, name: str, suffix: str) -> str:
        return str(self.folder / (name + suffix))

    def has(self, name: str) -> bool:
        return (self.folder / (name + META)).is_file()

    def meta_text(self, name: str) -> str:
        path = self.folder / (name + META)
        if not path.is_file():
            raise ValueError(f"{path}: no such file")
        if path.stat().st_size > MAX_META_BYTES:
            raise ValueError(f"{path}: {path.stat().st_size} bytes, too large for SigMF metadata")
        return path.read_text(encoding="utf-8", errors="replace")

    def samples(self, name: str) -> np.ndarray:
        path = self.folder / (name + DATA)
        if not path.is_file():
            raise ValueError(f"{path}: no such file")
        if path.stat().st_size == 0:
            return np.zeros(0, "<c8")
        return np.memmap(path, "<c8", mode="r")


class Archive:
    """The members of an uncompressed SigMF archive (a tar), read in place."""

    def __init__(self, path: Path):
        self.path = path
        lower = path.name.lower()
        if lower.endswith(COMPRESSED_ARCHIVES):
            raise ValueError(
                f"{path}: a compressed SigMF archive: unpack it (tar xf / unzip) and give its "
                ".sigmf-meta, or archive it uncompressed (.sigmf)"
            )
        try:
            with tarfile.open(path, "r:") as tar:  # "r:": uncompressed only
                members = [m for m in tar.getmembers() if m.isfile()]
                sparse = [m.name for m in members if m.issparse()]
                if sparse:  # its declared sizes are not bytes the file holds
                    raise ValueError(f"{sparse[0]}: a sparse member: not a SigMF archive")
                metas = [m for m in members if m.name.endswith(META)]
                # every metadata member is read whole: their total is bounded before any read
                total = sum(m.size for m in metas)
                if total > MAX_META_BYTES:
                    raise ValueError(
                        f"{len(metas)} metadata member(s) of {total} bytes in all, over the "
                        f"{MAX_META_BYTES}-byte limit for SigMF metadata"
                    )
                self._meta = {_base(m.name, META): tar.extractfile(m).read() for m in metas}
        except (tarfile.TarError, OSError, EOFError) as exc:
            raise ValueError(f"{path}: not a SigMF archive (an uncompressed tar): {exc}") from None
        # Data members: where their bytes lie in the archive file.
        self._data = {
            _base(m.name, DATA): (m.offset_data, m.size) for m in members if m.name.endswith(DATA)
        }
        size = path.stat().st_size
        for name, (offset, length) in self._data.items():
            if offset + length > size:
                raise ValueError(f"{path}: the archive is cut short (its {name}{DATA} is)")
        if not self._meta:
            raise ValueError(f"{path}: a tar without a .sigmf-meta member: not a SigMF archive")

    def names(self) -> list[str]:
        return sorted(self._meta)

    def describe(self, name: str, suffix: str) -> str:
        return f"{self.path}[{name}{suffix}]"

    def has(self, name: str) -> bool:
        return name in self._meta

    def meta_text(self, name: str) -> str:
        if name not in self._meta:
            raise ValueError(f"{self.path}: no member {name}{META}")
        return self._meta[name].decode("utf-8", "replace")

    def samples(self, name: str) -> np.ndarray:
        if name not in self._data:
            raise ValueError(f"{self.path}: no member {name}{DATA}")
        offset, length = self._data[name]
        if length == 0:
            return np.zeros(0, "<c8")
        if length % 8:
            raise ValueError(
                f"{self.path}: {name}{DATA} holds {length} bytes, not whole cf32 samples"
            )
        return np.memmap(self.path, "<c8", mode="r", offset=offset, shape=(length // 8,))


def _base(member: str, suffix: str) -> str:
    """A member's recording name: ``dir/NAME.sigmf-meta`` → ``NAME``."""
    return member.rsplit("/", 1)[-1][: -len(suffix)]


def sigmf_base(path: Path) -> Path | None:
    """The base name of a SigMF recording named by any of its files; None if not SigMF."""
    path = Path(path)
    for suffix in SUFFIXES:
        if path.name.lower().endswith(suffix):
            return path.with_name(path.name[: -len(suffix)])
    return None
