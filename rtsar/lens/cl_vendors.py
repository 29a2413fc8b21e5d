"""OpenCL drivers installed with pip into this environment, registered for the ICD loader.

An OpenCL program finds its drivers through the ICD loader (``libOpenCL``; pyopencl bundles
ocl-icd), which reads the ``*.icd`` files of a vendors folder, ``/etc/OpenCL/vendors`` unless
the environment variable ``OCL_ICD_VENDORS`` names another.  A driver installed with pip has no
such file, so nothing would find it.  Before the loader's first call, :func:`register` looks
for the drivers pip can install:

* Intel's CPU runtime (``pip install intel-opencl-rt intel-cmplr-lib-rt``): ``libintelocl.so``
  in the ``lib`` folder of the environment (any x86-64 CPU, AMD's included);

and, where one is found and ``OCL_ICD_VENDORS`` is unset, writes a vendors folder inside the
environment (``<prefix>/etc/OpenCL/vendors``: one ``.icd`` per driver found there, beside a
copy of every system ``.icd``, so the system's drivers stay visible) and points
``OCL_ICD_VENDORS`` at it.  Nothing is written outside the environment and nothing needs root;
where the environment is read-only the folder is a private temporary one, removed at exit.
pyopencl's own PoCL (``pyopencl[pocl]``) is found by its bundled loader in any case.

A user's own ``OCL_ICD_VENDORS`` is never replaced (:func:`register` then says so and does
nothing).  Child processes inherit the variable, so they see the same drivers.
"""

from __future__ import annotations

import atexit
import os
import shutil
import sys
import sysconfig
import tempfile
import threading
from dataclasses import dataclass
from pathlib import Path

__all__ = ["PIP_DRIVERS", "Registration", "find_pip_drivers", "register", "registration"]

SYSTEM_VENDORS = Path("/etc/OpenCL/vendors")
ENV_VENDORS = "OCL_ICD_VENDORS"

# icd file name -> (library file name, the pip command that installs it)
PIP_DRIVERS = {
    "rtsar-intel-cpu.icd": (
        "libintelocl.so",
        "pip install intel-opencl-rt intel-cmplr-lib-rt",
    ),
}


@dataclass(frozen=True)
class Registration:
    """What :func:`register` did: the drivers found (icd name -> library path), the vendors
    folder the loader reads, a one-line account for ``rtsar devices``, and whether the drivers
    found are visible (``registered``: rtsar's own folder lists them)."""

    drivers: dict
    vendors_dir: str | None
    note: str
    registered: bool = False


_lock = threading.Lock()
_done: Registration | None = None


def _lib_dirs() -> list[Path]:
    """Folders where pip puts a wheel's ``data/lib`` files: the environment's, the user's."""
    dirs = []
    for scheme_path in (sysconfig.get_path("data"), sys.prefix, sys.exec_prefix):
        if scheme_path:
            dirs.append(Path(scheme_path) / "lib")
    try:
        import site

        dirs.append(Path(site.getuserbase()) / "lib")
    except (ImportError, AttributeError):  # pragma: no cover - embedded interpreters
        pass
    seen, out = set(), []
    for d in dirs:
        key = str(d)
        if key not in seen:
            seen.add(key)
            out.append(d)
    return out


def find_pip_drivers() -> dict[str, str]:
    """The pip-installed drivers present: icd file name -> absolute library path."""
    found = {}
    for icd, (lib, _) in PIP_DRIVERS.items():
        for folder in _lib_dirs():
            path = folder / lib
            if path.is_file():
                found[icd] = str(path.resolve())
                break
    return found


def _write_vendors(folder: Path, drivers: dict[str, str]) -> None:
    """Fill ``folder`` with the system's ``.icd`` files and one per pip driver (idempotent)."""
    folder.mkdir(parents=True, exist_ok=True)
    wanted = {}
    if SYSTEM_VENDORS.is_dir():
        for icd in sorted(SYSTEM_VENDORS.glob("*.icd")):
            try:
                wanted[f"system-{icd.name}"] = icd.read_text(encoding="utf-8", errors="replace")
            except OSError:
                continue
    for icd, lib in drivers.items():
        wanted[icd] = lib + "\n"
    for old in folder.glob("*.icd"):
        if old.name not in wanted:
            old.unlink(missing_ok=True)
    for name, text in wanted.items():
        path = folder / name
        try:
            if path.read_text(encoding="utf-8", errors="replace") == text:
                continue
        except OSError:
            pass
        tmp = folder / f".{name}.{os.getpid()}.tmp"
        tmp.write_text(text, encoding="utf-8")
        os.replace(tmp, path)


def register(environ=None) -> Registration:
    """Make the pip-installed OpenCL drivers of this environment visible to the ICD loader.

    Call before the first OpenCL call of the process (``rtsar.lens.cl_loader`` does, on
    import).  Idempotent; returns what it did.
    """
    global _done
    env = os.environ if environ is None else environ
    with _lock:
        if _done is not None and environ is None:
            return _done
        drivers = find_pip_drivers()
        if not drivers:
            result = Registration({}, env.get(ENV_VENDORS) or None, "no pip-installed driver")
        elif env.get(ENV_VENDORS):
            result = Registration(
                drivers,
                env[ENV_VENDORS],
                f"{ENV_VENDORS} is set by the user ({env[ENV_VENDORS]}): the pip-installed "
                f"drivers ({', '.join(sorted(drivers.values()))}) are seen only if it lists them",
            )
        else:
            folder = Path(sys.prefix) / "etc" / "OpenCL" / "vendors"
            try:
                _write_vendors(folder, drivers)
                where = "inside the environment"
            except OSError:  # a read-only environment: a private folder for this process
                folder = Path(tempfile.mkdtemp(prefix="rtsar-opencl-vendors-"))
                atexit.register(shutil.rmtree, folder, True)
                _write_vendors(folder, drivers)
                where = "in a temporary folder (the environment is read-only)"
            env[ENV_VENDORS] = str(folder)
            result = Registration(
                drivers,
                str(folder),
                f"registered {', '.join(sorted(drivers.values()))} for the ICD loader "
                f"({ENV_VENDORS}={folder}, {where})",
                registered=True,
            )
        if environ is None:
            _done = result
        return result


def registration() -> Registration | None:
    """What :func:`register` did in this process (None before it ran)."""
    return _done
