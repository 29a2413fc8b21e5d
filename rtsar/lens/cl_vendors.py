"""OpenCL drivers installed with pip into this environment, registered for the ICD loader.

An OpenCL program finds its drivers through the ICD loader (``libOpenCL``; pyopencl bundles
ocl-icd), which reads the ``*.icd`` files of a vendors folder: ``OCL_ICD_VENDORS``, else
``OPENCL_VENDOR_PATH``, else ``/etc/OpenCL/vendors``.  A driver installed with pip has no such
file, so nothing would find it.  Before the loader's first call, :func:`register` looks for the
drivers pip can install:

* Intel's CPU runtime (``pip install intel-opencl-rt intel-cmplr-lib-rt``): ``libintelocl.so``
  in the ``lib`` folder of the environment (any x86-64 CPU, AMD's included);

and, where one is found and ``OCL_ICD_VENDORS`` is unset, writes a vendors folder of rtsar's
own inside the environment (``<prefix>/share/rtsar/opencl-vendors``): a copy of every ``.icd``
file the loader would have read (``OPENCL_VENDOR_PATH`` or ``/etc/OpenCL/vendors``, and the
environment's own ``<prefix>/etc/OpenCL/vendors``, conda's), so those drivers stay visible, and
one ``.icd`` per pip driver; then points ``OCL_ICD_VENDORS`` at it.  Only files rtsar wrote are
ever replaced or removed there.  Nothing is written outside a virtual environment and nothing
needs root: outside one, or where it is read-only, the folder is a private temporary one,
removed at exit.  pyopencl's own PoCL (``pyopencl[pocl]``) is found by its bundled loader in
any case.

A user's own ``OCL_ICD_VENDORS`` is never replaced (:func:`register` then says so and does
nothing).  Child processes inherit the variable, so they see the same drivers (and know the
folder is rtsar's: its ``.icd`` files name the pip drivers).
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
ENV_VENDOR_PATH = "OPENCL_VENDOR_PATH"  # ocl-icd's other variable (OCL_ICD_VENDORS wins)
OWN_PREFIXES = ("rtsar-", "copy-")  # the files rtsar writes in its folder

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
    """Folders where pip puts a wheel's ``data/lib`` files: the environment's (the user's too
    outside a virtual environment)."""
    dirs = []
    for scheme_path in (sysconfig.get_path("data"), sys.prefix, sys.exec_prefix):
        if scheme_path:
            dirs.append(Path(scheme_path) / "lib")
    if not _in_venv():  # pip install --user; a venv sees only its own packages
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


def _sources(env) -> list[Path]:
    """The vendors folders the loader would read without rtsar, and the environment's own."""
    system = Path(env[ENV_VENDOR_PATH]) if env.get(ENV_VENDOR_PATH) else SYSTEM_VENDORS
    own = Path(sys.prefix) / "etc" / "OpenCL" / "vendors"  # conda installs drivers' .icd here
    return [system] if own == system else [system, own]


def _write_vendors(folder: Path, drivers: dict[str, str], env) -> None:
    """Fill ``folder`` with copies of the loader's ``.icd`` files and one per pip driver
    (idempotent; only files rtsar wrote, ``OWN_PREFIXES``, are replaced or removed)."""
    folder.mkdir(parents=True, exist_ok=True)
    wanted = {}
    for k, source in enumerate(_sources(env)):
        if not source.is_dir():
            continue
        for icd in sorted(source.glob("*.icd")):
            try:
                text = icd.read_text(encoding="utf-8", errors="replace")
            except OSError:
                continue
            lib = text.strip()
            if os.path.isabs(lib) and not os.path.exists(lib):
                continue  # a dead entry (intel-opencl-rt ships one naming a conda build path)
            wanted[f"copy-{k}-{icd.name}"] = text
    for icd, lib in drivers.items():
        wanted[icd] = lib + "\n"
    seen = set()  # one file per library: the same driver listed twice is two devices
    for name in sorted(wanted, key=lambda n: not n.startswith("rtsar-")):
        lib = wanted[name].strip()
        if lib in seen:
            del wanted[name]
        seen.add(lib)
    for old in folder.glob("*.icd"):
        if old.name.startswith(OWN_PREFIXES) and old.name not in wanted:
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


def _lists(folder: str, drivers: dict[str, str]) -> bool:
    """True when the vendors folder ``folder`` already names every driver of ``drivers``."""
    try:
        named = {p.read_text(encoding="utf-8", errors="replace").strip()
                 for p in Path(folder).glob("*.icd")}  # fmt: skip
    except OSError:
        return False
    return set(drivers.values()) <= named


def _in_venv() -> bool:
    return sys.prefix != getattr(sys, "base_prefix", sys.prefix)


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
        elif env.get(ENV_VENDORS) and _lists(env[ENV_VENDORS], drivers):
            # set by an rtsar parent process (or by hand) and naming the drivers: nothing to do
            result = Registration(
                drivers, env[ENV_VENDORS], f"{ENV_VENDORS}={env[ENV_VENDORS]} lists them", True
            )
        elif env.get(ENV_VENDORS):
            result = Registration(
                drivers,
                env[ENV_VENDORS],
                f"{ENV_VENDORS} is set by the user ({env[ENV_VENDORS]}): the pip-installed "
                f"drivers ({', '.join(sorted(drivers.values()))}) are seen only if it lists them",
            )
        else:
            folder = Path(sys.prefix) / "share" / "rtsar" / "opencl-vendors"
            try:
                if not _in_venv():
                    raise PermissionError("not a virtual environment: no system folder written")
                _write_vendors(folder, drivers, env)
                where = "inside the environment"
            except OSError:  # read-only, or no venv: a private folder for this process
                folder = Path(tempfile.mkdtemp(prefix="rtsar-opencl-vendors-"))
                atexit.register(shutil.rmtree, folder, True)
                _write_vendors(folder, drivers, env)
                where = "in a temporary folder of this process"
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
