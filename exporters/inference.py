"""Texel inference with onnxruntime (docs/contracts.md §3): chunked, thread-settable, memory-bounded, NaN-guarded.

The model ``skin_inversion.onnx`` maps linear-sRGB albedo rows (N, 3) to the biophysical vector, the
exposure and, per wavelength of the 376-sample grid, the reflectance and K mixture components.  Its
outputs take about (6 + 376 (1 + 4K)) float32 per texel (19.6 KB for K = 3) and the collapse's float64
work arrays several times that, so texels are pushed through in chunks whose size follows a memory
budget (:func:`chunk_rows`).  Shapes and K are read from the graph, never assumed: a better model can
replace the shipped one.

Identical texels are evaluated once (:func:`unique_rows`): 8- and 16-bit textures repeat colours a lot.
"""

from __future__ import annotations

import os
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path

import numpy as np

from .constants import N_WAVELENGTHS
from .maps import sha256_file

INPUT_NAME = "albedo_rgb"
#: docs/contracts.md §3 outputs of skin_inversion.onnx and their shapes after the batch axis ("K" = components).
OUTPUT_SHAPES: dict[str, tuple] = {
    "biophysical": (5,),
    "exposure": (1,),
    "reflectance": (N_WAVELENGTHS,),
    "alpha": ("K", N_WAVELENGTHS),
    "sigma_t": ("K", N_WAVELENGTHS),
    "g": ("K", N_WAVELENGTHS),
    "weight": ("K", N_WAVELENGTHS),
}
#: Default memory budget of one inference chunk (ONNX outputs + collapse work arrays), MiB.
DEFAULT_MEMORY_MB: int = 512
#: Bytes per texel of the collapse's float64 work arrays, per component and wavelength (measured upper
#: bound: about 10 float64 arrays of shape (K, 236 visible wavelengths) live at once, rounded up).
_COLLAPSE_BYTES_PER_KL = 10 * 8


#: onnxruntime session runs and texels evaluated by every InversionSession of this process (read by tests and
#: benchmarks to prove that a step did no inference; :func:`inference_counts`).
_COUNTS = {"runs": 0, "texels": 0}


def inference_counts() -> dict[str, int]:
    """How many onnxruntime session runs (``runs``) on how many texels (``texels``) this process has done."""
    return dict(_COUNTS)


class ModelError(ValueError):
    """The model file is missing, not ONNX, or not of the docs/contracts.md §3 shape; the message says which."""


def _dims(shape) -> tuple:
    return tuple(d if isinstance(d, int) else None for d in shape)


@dataclass
class InversionSession:
    """An onnxruntime session on ``skin_inversion.onnx`` with its docs/contracts.md §3 shapes checked.

    ``k``: number of mixture components (read from the graph); ``sha256``: of the model file;
    ``threads``: intra-op threads (0 = onnxruntime's default, all cores).
    """

    path: Path
    k: int
    sha256: str
    threads: int
    session: object = field(repr=False)

    def bytes_per_texel(self) -> int:
        """Peak bytes per texel of one inference + collapse step (used to size chunks)."""
        return bytes_per_texel(self.k)

    def run(self, rgb: np.ndarray) -> dict[str, np.ndarray]:
        """Evaluate rows ``rgb`` (N, 3) linear sRGB in one call; returns every output as float32 arrays.

        Raises ValueError on non-finite input (the graph would silently substitute a fallback colour)
        and RuntimeError if the model produced non-finite values.
        """
        x = np.asarray(rgb)
        if x.ndim != 2 or x.shape[1] != 3:
            raise ValueError(f"albedo rows must have shape (N, 3), got {x.shape}")
        bad = ~np.isfinite(x).all(axis=1)
        if bad.any():
            raise ValueError(f"{int(bad.sum())} albedo texel(s) are NaN/Inf (first row {int(np.argmax(bad))}); "
                             "fix the texture")
        with np.errstate(over="ignore"):
            x = x.astype(np.float32)
        big = ~np.isfinite(x).all(axis=1)
        if big.any():
            raise ValueError(f"{int(big.sum())} albedo texel(s) exceed the float32 range (first row "
                             f"{int(np.argmax(big))}); an albedo lies in [0, 1]")
        names = list(OUTPUT_SHAPES)
        if len(x) == 0:  # onnxruntime warns on empty batches; the answer is known
            return {n: np.zeros((0, *(self.k if d == "K" else d for d in OUTPUT_SHAPES[n])), np.float32)
                    for n in names}
        values = self.session.run(names, {INPUT_NAME: np.ascontiguousarray(x)})
        _COUNTS["runs"] += 1
        _COUNTS["texels"] += len(x)
        out = dict(zip(names, values, strict=True))
        for name, value in out.items():
            if not np.all(np.isfinite(value)):
                raise RuntimeError(f"model {self.path.name} produced NaN/Inf in '{name}' for "
                                   f"{int((~np.isfinite(value)).reshape(len(x), -1).any(axis=1).sum())} texel(s)")
        return out

    def run_chunks(self, rgb: np.ndarray, chunk: int) -> Iterator[tuple[slice, dict[str, np.ndarray]]]:
        """Yield (row slice, outputs) for consecutive chunks of at most ``chunk`` rows."""
        if chunk < 1:
            raise ValueError("chunk must be >= 1")
        for start in range(0, len(rgb), chunk):
            sl = slice(start, min(start + chunk, len(rgb)))
            yield sl, self.run(rgb[sl])


def bytes_per_texel(k: int) -> int:
    """Peak bytes per texel of one inference + collapse step for K components (ONNX outputs + collapse)."""
    onnx_out = 4 * (5 + 1 + N_WAVELENGTHS * (1 + 4 * k))
    return onnx_out + _COLLAPSE_BYTES_PER_KL * k * N_WAVELENGTHS


def chunk_rows(model: InversionSession, memory_mb: float = DEFAULT_MEMORY_MB) -> int:
    """Texels per chunk so that one chunk stays within ``memory_mb`` MiB (at least 1)."""
    return chunk_rows_for_k(model.k, memory_mb)


def chunk_rows_for_k(k: int, memory_mb: float = DEFAULT_MEMORY_MB) -> int:
    """:func:`chunk_rows` for a model of K components (without loading it)."""
    if not memory_mb > 0:
        raise ValueError("memory budget must be > 0 MiB")
    return max(1, int(memory_mb * 2**20 // bytes_per_texel(k)))


def onnx_session(model: str | os.PathLike | bytes, threads: int = 0):
    """An onnxruntime ``InferenceSession`` on the CPU for an ONNX file path or the graph's serialised bytes:
    ``threads`` intra-op threads (0 = onnxruntime's default, all cores), one inter-op thread, only errors
    logged.  Every session of the project is made here (inversion, decoder, export parity, benchmarks).
    ValueError for ``threads`` < 0; onnxruntime's own exception for a file that is not a valid graph."""
    import onnxruntime as ort  # imported here: ~0.3 s, and only inference needs it

    if threads < 0:
        raise ValueError("threads must be >= 0 (0 = all cores)")
    opts = ort.SessionOptions()
    opts.intra_op_num_threads = int(threads)
    opts.inter_op_num_threads = 1
    opts.log_severity_level = 3
    source = model if isinstance(model, bytes) else str(model)
    return ort.InferenceSession(source, sess_options=opts, providers=["CPUExecutionProvider"])


def load_model(path: str | os.PathLike, threads: int = 0) -> InversionSession:
    """Open ``skin_inversion.onnx`` on the CPU and check it is of the docs/contracts.md §3 shape.

    ``threads``: onnxruntime intra-op threads, 0 = all cores.  Errors (:class:`ModelError`) name the file
    and what is wrong: missing, unreadable / not ONNX, wrong input, missing or mis-shaped outputs.
    """
    path = Path(path)
    if not path.is_file():
        raise ModelError(f"model not found at {path}: train/export it (python -m training export) or set the "
                         "model path")
    if threads < 0:
        raise ValueError("threads must be >= 0 (0 = all cores)")
    try:
        session = onnx_session(path, threads=threads)
    except Exception as exc:  # onnxruntime raises its own exception types for bad files
        raise ModelError(f"cannot load model {path}: not a valid ONNX file ({str(exc).splitlines()[0][:200]})"
                         ) from None
    inputs = session.get_inputs()
    if len(inputs) != 1 or inputs[0].name != INPUT_NAME or len(inputs[0].shape) != 2 or _dims(inputs[0].shape)[1] != 3:
        got = [(i.name, list(i.shape)) for i in inputs]
        raise ModelError(f"model {path.name} has inputs {got}; expected one input '{INPUT_NAME}' of shape (N, 3) "
                         "(docs/contracts.md §3 skin_inversion.onnx)")
    outputs = {o.name: _dims(o.shape) for o in session.get_outputs()}
    missing = [n for n in OUTPUT_SHAPES if n not in outputs]
    if missing:
        raise ModelError(f"model {path.name} lacks output(s) {missing}; expected {list(OUTPUT_SHAPES)} "
                         "(docs/contracts.md §3)")
    k = _read_k(session, path, outputs)
    for name, tail in OUTPUT_SHAPES.items():
        want = tuple(k if d == "K" else d for d in tail)
        got = outputs[name][1:]
        if len(got) != len(want) or any(g is not None and g != w for g, w in zip(got, want, strict=True)):
            raise ModelError(f"model {path.name}: output '{name}' has shape {list(outputs[name])}, expected "
                             f"(N, {', '.join(map(str, want))}) (docs/contracts.md §3)")
    model = InversionSession(path=path, k=k, sha256=sha256_file(path), threads=int(threads), session=session)
    probe = model.run(np.array([[0.4, 0.3, 0.25]], dtype=np.float32))  # shapes of a real evaluation
    for name, tail in OUTPUT_SHAPES.items():
        want = (1, *(k if d == "K" else d for d in tail))
        if probe[name].shape != want:
            raise ModelError(f"model {path.name}: output '{name}' evaluates to shape {probe[name].shape}, "
                             f"expected {want} (docs/contracts.md §3)")
    return model


def _read_k(session, path: Path, outputs: dict[str, tuple]) -> int:
    k = outputs["alpha"][1] if len(outputs["alpha"]) == 3 else None
    if k is None:  # symbolic K: evaluate one row
        alpha = session.run(["alpha"], {INPUT_NAME: np.array([[0.4, 0.3, 0.25]], dtype=np.float32)})[0]
        if alpha.ndim != 3:
            raise ModelError(f"model {path.name}: output 'alpha' has rank {alpha.ndim}, expected (N, K, 376)")
        k = alpha.shape[1]
    if k < 1:
        raise ModelError(f"model {path.name}: K = {k} components")
    return int(k)


def unique_rows(rgb: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distinct rows of a float32 (N, 3) array and the inverse index (``uniq[inverse] == rgb``).

    Rows are compared bit for bit (a 12-byte void view), so the result is exact; ordering is not
    meaningful.
    """
    x = np.ascontiguousarray(rgb, dtype=np.float32)
    if x.ndim != 2 or x.shape[1] != 3:
        raise ValueError(f"rows must have shape (N, 3), got {x.shape}")
    x = x + np.float32(0.0)  # -0.0 -> +0.0 so that equal values have equal bits
    keys = x.view(np.dtype((np.void, 12))).ravel()
    _, first, inverse = np.unique(keys, return_index=True, return_inverse=True)
    return x[first], inverse.ravel()


class ModelFile:
    """``skin_inversion.onnx`` on disk, opened with onnxruntime only when first needed (:meth:`load`): a bake
    served entirely by the fast-path table, or found up to date, never loads the model.  ``sha256`` hashes
    the file (cheap); a missing file raises :class:`ModelError` there and in :meth:`load`."""

    def __init__(self, path: str | os.PathLike, threads: int = 0) -> None:
        self.path = Path(path)
        self.threads = int(threads)
        self._model: InversionSession | None = None
        self._sha256: str | None = None
        if not self.path.is_file():
            raise ModelError(f"model not found at {self.path}: train/export it (python -m training export) or set "
                             "the model path")
        if self.threads < 0:
            raise ValueError("threads must be >= 0 (0 = all cores)")

    @property
    def sha256(self) -> str:
        if self._sha256 is None:
            self._sha256 = self._model.sha256 if self._model is not None else sha256_file(self.path)
        return self._sha256

    @property
    def loaded(self) -> bool:
        return self._model is not None

    def load(self) -> InversionSession:
        if self._model is None:
            self._model = load_model(self.path, threads=self.threads)
        return self._model

    @classmethod
    def of(cls, model: InversionSession) -> ModelFile:
        """Wrap an already loaded model."""
        ref = cls(model.path, model.threads)
        ref._model = model
        return ref


@cache
def _decoder_session(path: str, mtime_ns: int, size: int):
    """One single-threaded session per decoder file version (a file replaced on disk gets a new one)."""
    return onnx_session(path, threads=1)


def run_decoder(biophysical: np.ndarray, path: str | os.PathLike,
                outputs: Sequence[str] | None = None) -> dict[str, np.ndarray]:
    """``skin_decoder.onnx`` at ``path`` on biophysical rows (N, 5) of docs/contracts.md §1 (t_epi in cm): the
    outputs named in ``outputs`` (default: every output; reflectance (N, 376); alpha, sigma_t, g, weight
    (N, K, 376)) by name, float64.  ValueError if the file is missing; the outputs are returned as the graph
    gives them (callers check what they use)."""
    p = Path(path)
    if not p.is_file():
        raise ValueError(f"decoder model {p} not found; pass the path of skin_decoder.onnx.")
    stat = p.stat()
    sess = _decoder_session(str(p.resolve()), stat.st_mtime_ns, stat.st_size)
    names = [o.name for o in sess.get_outputs()] if outputs is None else list(outputs)
    rows = np.asarray(biophysical, dtype=np.float32).reshape(-1, 5)
    out = sess.run(names, {"biophysical": rows})
    return {n: np.asarray(v, dtype=np.float64) for n, v in zip(names, out, strict=True)}
