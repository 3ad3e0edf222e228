"""Verified loading of the ONNX models the project ships (the depth model, the learned policy).

Owns `ModelFileError`, the one error type for a model file that is missing, empty, truncated, tampered
with or not loadable (each model's own error subclasses it), `open_verified_session`: SHA-256 check,
then an onnxruntime session with one intra-op thread and sequential execution (deterministic outputs),
and `shipped_assets_dir`, where the shipped files are.
"""

from __future__ import annotations

import hashlib
import importlib.util
import re
import sys
from pathlib import Path

import onnxruntime as ort

SHA256_RE = re.compile(r"[0-9a-f]{64}")
# The package of the shipped data files: the repo's assets/ folder, installed under trade_gym (pyproject.toml)
ASSETS_PACKAGE = "trade_gym.assets"


class ModelFileError(Exception):
    """A model file is missing, empty, truncated, tampered with or not a usable ONNX model; names the file."""


def check_sha256_format(expected_sha256: str) -> None:
    """ValueError unless `expected_sha256` is 64 lowercase hex digits."""
    if not isinstance(expected_sha256, str) or not SHA256_RE.fullmatch(expected_sha256):
        raise ValueError(f"expected_sha256 must be 64 lowercase hex digits, got {expected_sha256!r}")


def open_verified_session(path: Path, expected_sha256: str, what: str,
                          error: type[ModelFileError] = ModelFileError) -> ort.InferenceSession:
    """Read `path`, check its SHA-256 against `expected_sha256`, build a single-threaded CPU session.

    `what` names the file's role in messages ("depth model file", "policy file"); failures raise `error`."""
    if not path.is_file():
        raise error(f"{what} {path} is missing")
    data = path.read_bytes()
    if not data:
        raise error(f"{what} {path} is empty")
    digest = hashlib.sha256(data).hexdigest()
    if digest != expected_sha256:
        raise error(f"{what} {path} has SHA-256 {digest}, expected {expected_sha256} "
                    "(truncated, tampered with or a different model)")
    options = ort.SessionOptions()
    options.intra_op_num_threads = 1
    options.inter_op_num_threads = 1
    options.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
    options.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    try:
        return ort.InferenceSession(data, options, providers=["CPUExecutionProvider"])
    except Exception as exc:  # onnxruntime raises its own (non-public) exception types
        raise error(f"{what} {path} is not a loadable ONNX model: {exc}") from exc


def shipped_assets_dir() -> Path:
    """The folder of the `trade_gym.assets` package, found as `import` finds it but without importing `trade_gym`
    (the stack never loads the simulator): site-packages/trade_gym/assets from a wheel, the repo's assets/ folder
    from an editable install (setuptools' import hook maps the package there)."""
    parent = importlib.util.find_spec("trade_gym")  # a top-level name: located, not imported
    locations = list(parent.submodule_search_locations or []) if parent is not None else []
    # the import system's search for a submodule: each finder on sys.meta_path, given the parent package's path
    for finder in sys.meta_path if locations else ():
        find_spec = getattr(finder, "find_spec", None)
        spec = find_spec(ASSETS_PACKAGE, locations) if find_spec is not None else None
        if spec is not None and spec.origin is not None:
            return Path(spec.origin).resolve().parent
    raise ModuleNotFoundError(f"no package {ASSETS_PACKAGE!r} (the shipped model files) on this Python's path; "
                              "install trade-gym", name=ASSETS_PACKAGE)
