"""Weight files of the learned planners: the state dict, the architecture and what produced them.

A file is a ``torch.save`` dictionary ``{"format", "version", "kind", "spec", "state_dict",
"metadata"}`` written atomically; loading rebuilds the network from ``spec``, checks every tensor's
shape and reports a wrong, truncated or foreign file as one :class:`InputFileError` naming it.
"""

from __future__ import annotations

import io
from functools import lru_cache
from pathlib import Path

import torch

from tpvp.errors import InputFileError
from tpvp.io.atomic import atomic_write_bytes
from tpvp.learning.models import ARCHITECTURES, build_model

FORMAT = "tpvp-learned-planner"
VERSION = 1
SHIPPED = Path(__file__).resolve().parent.parent / "data" / "learning"


def shipped_path(kind: str) -> Path:
    """The weights shipped with the package (``tpvp/data/learning/<kind>.pt``)."""
    return SHIPPED / f"{kind}.pt"


def save_weights(path, model: torch.nn.Module, kind: str, metadata: dict | None = None) -> Path:
    """Write ``model``'s weights (float32) with its architecture and ``metadata`` (plain data)."""
    payload = {"format": FORMAT, "version": VERSION, "kind": kind, "spec": model.spec,
               "state_dict": {k: v.detach().cpu().clone() for k, v in model.state_dict().items()},
               "metadata": metadata or {}}
    buffer = io.BytesIO()
    torch.save(payload, buffer)
    return atomic_write_bytes(path, buffer.getvalue())


def load_weights(path, kind: str) -> tuple[torch.nn.Module, dict]:
    """The network stored at ``path`` (eval mode) and its metadata; checks the file is a ``kind``
    weight file whose tensors have the shapes of the architecture it names."""
    path = Path(path)
    if not path.is_file():
        raise InputFileError(f"{path}: no such weight file; train one with python -m tpvp.learning train")
    try:
        payload = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # torch raises many types for a damaged archive
        raise InputFileError(f"{path}: not a readable weight file ({type(exc).__name__}: "
                             f"{str(exc).splitlines()[0] if str(exc) else 'damaged'})") from None
    if not isinstance(payload, dict) or payload.get("format") != FORMAT:
        raise InputFileError(f"{path}: not a tpvp learned-planner weight file")
    if payload.get("kind") != kind or kind not in ARCHITECTURES:
        raise InputFileError(f"{path}: holds {payload.get('kind')!r} weights, {kind!r} were asked for")
    try:
        model = build_model(kind, payload["spec"])
    except (TypeError, ValueError, KeyError) as exc:
        raise InputFileError(f"{path}: its architecture ({payload.get('spec')}) cannot be built: {exc}") from None
    expected = model.state_dict()
    stored = payload.get("state_dict")
    if not isinstance(stored, dict):
        raise InputFileError(f"{path}: no state dict")
    if missing := sorted(set(expected) - set(stored)):
        raise InputFileError(f"{path}: {len(missing)} tensors missing, e.g. {missing[0]}")
    if extra := sorted(set(stored) - set(expected)):
        raise InputFileError(f"{path}: {len(extra)} unexpected tensors, e.g. {extra[0]}")
    for name, tensor in expected.items():
        if tuple(stored[name].shape) != tuple(tensor.shape):
            raise InputFileError(f"{path}: tensor {name} has shape {tuple(stored[name].shape)}, the architecture "
                                 f"needs {tuple(tensor.shape)}")
    model.load_state_dict(stored)
    model.eval()
    return model, payload.get("metadata", {})


@lru_cache(maxsize=4)
def cached_model(kind: str, path: str | None = None):
    """:func:`load_weights` once per process (the shipped file when ``path`` is None)."""
    return load_weights(path or shipped_path(kind), kind)
