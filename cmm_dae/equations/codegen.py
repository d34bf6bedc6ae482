"""Evaluating CasADi functions from Python: through their buffer API into numpy arrays
(:class:`Buffered`), or compiled to C and loaded back (:func:`compile_functions`)."""

from __future__ import annotations

import ctypes
import hashlib
import os
import shlex
import shutil
import subprocess
import threading
import warnings
from collections import OrderedDict
from pathlib import Path

import casadi as ca
import numpy as np

from . import libcache
from .libcache import cache_dir


class Buffered:
    """A CasADi function evaluated through its buffer API (about 3 us instead of 30 us a
    call from Python): the one way the package evaluates its compiled functions.

    ``fixed``: the values of the last input, bound once (a lifted function's constants).
    Two uses: ``f(*args)`` copies the arguments in and returns fresh numpy arrays (vectors
    1-D, matrices 2-D); for hot callbacks, :meth:`bind` and :meth:`bind_out` point the
    function at caller-owned arrays once and :meth:`run` evaluates it without any copy.
    """

    def __init__(self, fn: ca.Function, sparse: bool = False, fixed: np.ndarray | None = None):
        self.fn = fn
        self.buf, self._call = fn.buffer()
        self.args = [np.zeros(fn.nnz_in(i)) for i in range(fn.n_in())]
        if fixed is not None:  # the last input, bound for good (a lifted function's
            # constants, :mod:`.lifting`): calls give the others
            self.args[-1] = np.ascontiguousarray(fixed, dtype=float).copy()
        for i, a in enumerate(self.args):
            self.buf.set_arg(i, memoryview(a))
        self._free = len(self.args) - (fixed is not None)
        self.outs = [np.zeros(fn.nnz_out(i)) for i in range(fn.n_out())]
        for i, o in enumerate(self.outs):
            self.buf.set_res(i, memoryview(o))
        self.shapes = [fn.size_out(i) for i in range(fn.n_out())]
        for i in range(fn.n_out()):  # sparse: outputs are the nonzeros in CSC order
            if not sparse and fn.nnz_out(i) != self.shapes[i][0] * self.shapes[i][1]:
                raise ValueError(f"output {i} of {fn.name()} must be dense")

    def bind(self, i: int, arr: np.ndarray) -> None:
        """Read input ``i`` straight from ``arr`` (contiguous float64, kept alive by the
        caller) at every :meth:`run`."""
        self.args[i] = arr
        self.buf.set_arg(i, memoryview(arr))

    def bind_out(self, i: int, arr: np.ndarray) -> None:
        """Write output ``i`` straight into ``arr`` (column-major order) at :meth:`run`."""
        self.outs[i] = arr
        self.buf.set_res(i, memoryview(arr))

    def run(self) -> None:
        """Evaluate with the bound arrays."""
        self._call()

    def __call__(self, *args) -> list[np.ndarray]:
        for a, x in zip(self.args[:self._free], args, strict=True):
            if type(x) is np.ndarray and x.ndim > 1:  # (np.ndim: 0.6 us a call)
                a[:] = np.ravel(x, order="F")  # CasADi is column-major
            else:
                a[:] = x
        self._call()
        if self.buf.ret():  # a failed evaluation (a linear solve or a root-finder inside
            # an MX function) leaves the outputs as they were: never return those
            raise RuntimeError(f"the evaluation of CasADi function '{self.fn.name()}' failed")
        # CasADi stores column-major: a (r, c) matrix is the transpose of a (c, r) C-array,
        # copied as it lies (a Fortran-ordered array: a C-ordered copy gathered it element
        # by element, 1.1 ms for the 770 x 771 Jacobian of A02 with 128 loops, 4.6 of a
        # run's 30 s)
        return [o.reshape(c, r).T.copy(order="K") if c > 1 else o.copy()
                for o, (r, c) in zip(self.outs, self.shapes, strict=True)]


def map_width(k: int, size: int) -> int:
    """The number of samples a mapped evaluation of ``k`` of them (at most ``size``, the
    chunk) is built for, the rest padding: ``size`` for a full chunk, else the least of
    2^j, 1.25, 1.5 or 1.75 times 2^j (at least 8) that holds k. The maps, which cost more
    to build than to run on a large model, stay few (four an octave); the padding is at
    most a quarter of the width (201 samples of a 2-s run take 224, where the next power
    of two took 256)."""
    if k >= size:
        return size
    base = max(8, 1 << max(k - 1, 1).bit_length() - 1)  # k <= 2 base
    return min(size, next(w for w in (base, 5 * base // 4, 3 * base // 2, 7 * base // 4,
                                      2 * base) if w >= k))


def addresses(lib: ctypes.CDLL, name: str) -> tuple[int, int]:
    """Addresses of a generated function ``name`` in a loaded library and of its
    work-size query (``name_work``), for C code that calls it."""
    return (ctypes.cast(getattr(lib, name), ctypes.c_void_p).value,
            ctypes.cast(getattr(lib, f"{name}_work"), ctypes.c_void_p).value)


def c_compiler() -> list[str] | None:
    """The system C compiler as a command (``$CC``, split like a shell would, so that
    ``CC="gcc -m64"`` works; else ``cc`` or ``gcc``), None when there is none."""
    cc = os.environ.get("CC", "").strip()
    if cc:
        return shlex.split(cc)
    found = shutil.which("cc") or shutil.which("gcc")
    return [found] if found else None


def _digest(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _stamp(lib: Path) -> Path:
    """The file written beside a library once its build is complete: key, size, sha256."""
    return lib.with_name(lib.name + ".ok")


def verified(lib: Path, key: str) -> bool:
    """True when ``lib`` is the complete library built under ``key``: its stamp names the
    key, and its size and checksum are the ones written after the build. A library is
    never loaded on its existence alone: a file cut short (a full disk, a killed build,
    a copy) mapped into the process kills it (SIGBUS), and another model's library under
    this name would compute another model."""
    try:
        words = _stamp(lib).read_text().split()
        return (len(words) == 3 and words[0] == key and int(words[1]) == lib.stat().st_size
                and words[2] == _digest(lib))
    except (OSError, ValueError):
        return False


class NotBuiltError(LookupError):
    """A library asked for with ``build=False`` is not in the cache (or fails its check)."""


def build_library(key: str, sources: list[Path] | None, funcs: list[ca.Function] = (),
                  flags: tuple[str, ...] = (), build: bool = True) -> Path:
    """A shared library ``cmm_<key>.so`` in :func:`cache_dir` built (unless a verified one
    is already there, see :func:`verified`) from C ``sources`` and the CasADi-generated C
    of ``funcs``; ``flags`` go to the linker. A cached file that fails the check is
    rebuilt with a one-line warning. Raises OSError / subprocess.SubprocessError /
    RuntimeError when it cannot be built, :class:`NotBuiltError` with ``build=False`` when it
    is not built already."""
    cache = cache_dir()
    lib = cache / f"cmm_{key}.so"
    if lib.is_file() and verified(lib, key):
        libcache.touch(lib)  # its last use orders the trimming
        return lib
    if not build:
        raise NotBuiltError(str(lib))
    cc = c_compiler()
    if cc is None:
        raise OSError("no C compiler found (set CC or install cc/gcc)")
    if lib.is_file():
        warnings.warn(f"the cached library {lib} is incomplete, changed or not this "
                      "model's (no matching size and checksum): rebuilding it", stacklevel=3)
    cache.mkdir(parents=True, exist_ok=True)
    files = [str(f) for f in sources or ()]
    generated = None
    if funcs:
        # named by the process as the library's temporary file is: two processes building
        # the same library (parallel test workers, a sweep's workers) must not compile a
        # C file the other is still writing
        gen = ca.CodeGenerator(f"cmm_{key}_{_builder()}.c")
        for f in funcs:
            gen.add(f)
        generated = Path(gen.generate(str(cache) + os.sep))
        files.append(str(generated))
    tmp = lib.with_suffix(f".{_builder()}.tmp")
    stamp_tmp = lib.with_suffix(f".{_builder()}.ok.tmp")
    try:
        # CasADi's generated code (straight-line arithmetic) at -O1: A02 with 32 loops
        # built in 13.7 s instead of 25.9 s, its segment and post-processing as fast
        # (15.24 ms a 2-s run's segments either way); hand-written C at -O2
        opt = "-O1" if funcs else "-O2"
        # no fused multiply-adds where the target has them (aarch64 by default): the C
        # functions round as CasADi's virtual machine does, so the compiled path and the
        # Python path take the same steps
        subprocess.run([*cc, opt, *BUILD_FLAGS.split(), "-fPIC", "-shared", *files, "-o",
                        str(tmp), *flags],
                       check=True, capture_output=True, timeout=600)
        stamp_tmp.write_text(f"{key} {tmp.stat().st_size} {_digest(tmp)}\n")
        # the stamp first, then the library, each atomic: a process that finds the
        # library finds its stamp (parallel runs never load a half-written library)
        stamp_tmp.replace(_stamp(lib))
        tmp.replace(lib)
    finally:
        if generated is not None:
            generated.unlink(missing_ok=True)
        tmp.unlink(missing_ok=True)
        stamp_tmp.unlink(missing_ok=True)
    libcache.touch(lib)
    libcache.trim(keep=lib)  # the cache's size cap: the least recently used go
    return lib


def _builder() -> str:
    """Names a build's temporary files: its process and thread (a background build and a
    run's own may build at once)."""
    return f"{os.getpid()}_{threading.get_ident()}"


#: Keys of the libraries asked for lately, by the identity of their functions (which the
#: entries hold, so that no identity is reused while its key is kept).
_KEYS: OrderedDict[tuple[int, ...], tuple[list, str]] = OrderedDict()
_KEYS_LOCK = threading.Lock()  # a background build asks too
KEYS_KEPT = 64


#: What the functions' libraries are compiled with beyond the optimization level, in their
#: key: a library built otherwise (before -ffp-contract=off) is never taken for one of these.
BUILD_FLAGS = "-ffp-contract=off"


def function_key(funcs: list[ca.Function]) -> str:
    """A short hash naming the library of ``funcs``, computed once for the same function
    objects: serializing them took 40 ms of every 0.01-s run of A02 with 32 loops under
    ``compiled="auto"``, which looks for a library built since the run before."""
    ids = tuple(id(f) for f in funcs)
    with _KEYS_LOCK:
        got = _KEYS.get(ids)
        if got is not None:
            _KEYS.move_to_end(ids)
            return got[1]
    key = hashlib.sha256(BUILD_FLAGS.encode()
                         + b"".join(f.serialize().encode() for f in funcs)).hexdigest()[:20]
    with _KEYS_LOCK:
        _KEYS[ids] = (list(funcs), key)
        while len(_KEYS) > KEYS_KEPT:
            _KEYS.popitem(last=False)
    return key


def compile_functions(funcs: list[ca.Function]) -> list[ca.Function] | None:
    """C code generation of CasADi functions, compiled by the system C compiler into a
    shared library cached under :func:`cache_dir`, keyed by a hash of the functions.
    Returns None, with a warning, when no compiler works: the caller keeps CasADi's
    virtual machine, which gives the same numbers.

    It pays only when the build (seconds) is amortised: the per-call gain is about 12 us
    on the nipper's 98 x 98 Jacobian (see validation/README.md).
    """
    try:
        lib = build_library(function_key(funcs), None, funcs)
        return [ca.external(f.name(), str(lib)) for f in funcs]
    except (OSError, subprocess.SubprocessError, RuntimeError) as e:
        warnings.warn(f"compiling the model failed ({e}): using CasADi's virtual machine",
                      stacklevel=3)
        return None
