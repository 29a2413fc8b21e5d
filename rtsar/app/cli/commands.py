"""The commands of ``rtsar``: name, the module of ``rtsar.app.cli`` that declares it, one line.

Read without importing any command module, so ``rtsar --help`` and ``rtsar --version`` load
nothing heavy, and ``rtsar COMMAND`` loads only the module that declares COMMAND (its
``add_parsers(sub)`` declares its commands; the one-line help is taken from here).
"""

from __future__ import annotations

COMMANDS = (  # in the order of ``rtsar --help``
    ("presets", "files", "list instrument presets and their theoretical figures"),
    ("import", "instrument",
     "a real instrument's raw data block (its instrument TOML) as a recording"),
    ("simulate", "files", "simulate the raw shots of a scene into a recording"),
    ("process", "files", "focus a recording through the streaming engine"),
    ("quicklook", "files", "PNG of an image file (dB; axes in km, m, mm or µm, by their span)"),
    ("run", "streaming",
     "live processing: the demo scene (default), a scene, or a serial instrument"),
    ("replay", "replay",
     "replay a recording through the pipeline at real rate, a factor, or max"),
    ("demo", "replay",
     "the 3D demo: InSAL heights of Zhao's ridge, published live (14-16 s after `rtsar prepare`)"),
    ("subscribe", "streaming", "record published strips into an image file"),
    ("keygen", "streaming", "make a CURVE key pair for encrypted publication"),
    ("view", "view",
     "live waterfall of published strips: a window, a PNG snapshot, or a browser page"),
    ("prepare", "prepare",
     "once after installing: compile the kernels and survey the OpenCL devices, so that first "
     "runs start as fast as later ones"),
    ("devices", "measure",
     "every OpenCL device: does it build the lens, is it right, how fast; the default"),
    ("measure", "measure",
     "an image's point targets: position, IRW, PSLR, ISLR against theory (and truth)"),
    ("bench", "measure",
     "throughput of the lens and correlators, and the live pipeline, in one run"),
    ("tradeoff", "measure",
     "what accuracy costs in time: every processor knob, quality against cost"),
    ("table1", "measure",
     "Psaltis & Wagner's Table 1 regenerated from the physical-mode emulation"),
    ("export", "formats", "a recording as CPHD or SigMF, an image as SICD"),
    ("batch", "batch",
     "focus many recordings with `process` on Dask (local processes or a cluster)"),
    ("swath-worker", "swath", "one range slice of a live pipeline split across processes or hosts"),
    ("spot-simulate", "spot", "simulate a spotlight collection (Crouch ch. 9) into a recording"),
    ("spotlight", "spot",
     "form a spotlight image: polar format (chirp-z) or backprojection; live/progressive"),
    ("projective", "spot",
     "projective SAL: two spotlight images a quarter turn apart → 3-D points (ch. 8)"),
)  # fmt: skip

HELP = {name: line for name, _, line in COMMANDS}
MODULE = {name: module for name, module, _ in COMMANDS}
