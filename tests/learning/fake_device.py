"""A second device for machines without one: `FakeDevice` runs a block as if the `meta`
device were an accelerator with its own memory, so that a test finds the device mix-ups that
crash training on a GPU ("Expected all tensors to be on the same device") on a CPU alone.

The tensors stay real CPU tensors and every computation runs as usual; the mode only tracks
which of them are "on the device": those moved there (`.to(device)`, a module's `.to`), made
there (`device=` of a factory function) or computed from such, and reports `device` as their
`.device`. An operation that takes tensors from both sides fails as CUDA does; as on CUDA, a
0-dimensional host tensor may join device tensors, `copy_` may copy across, and a device
tensor may be indexed by host indices. `.cpu()` brings a copy back; `.numpy()` of a device
tensor fails as it does on CUDA. What it cannot see: kernels CUDA lacks (it knows one,
torch.linalg.lstsq's drivers other than gels) and CUDA's own rounding; the tests marked for
CUDA (tests/learning/test_devices.py) run those where a GPU is.
"""

from __future__ import annotations

from typing import Any

import torch
from torch.overrides import TorchFunctionMode
from torch.utils._pytree import tree_flatten
from torch.utils.weak import WeakIdKeyDictionary

DEVICE = torch.device("meta")  # the name the device goes by; every build of torch knows it
HOST = torch.device("cpu")
# operations that may take tensors of both sides: copies, and what Module.to uses to move
# its parameters
_ACROSS = (torch.Tensor.copy_, torch._has_compatible_shallow_copy_type,
           torch.Tensor.data.__set__)


class FakeDevice(TorchFunctionMode):
    """Within the block, DEVICE behaves as a device of its own (see the module)."""

    def __init__(self) -> None:
        super().__init__()
        self._on_device: WeakIdKeyDictionary = WeakIdKeyDictionary()
        self.checked = 0  # operations checked: proof that the mode saw the work

    def __enter__(self) -> FakeDevice:
        # pickling (torch.save) asks a tensor's device outside the torch-function protocol:
        # there it must see where the data is, or it saves a device tensor as meta, without data
        self._pickle = torch.Tensor._reduce_ex_internal
        pickle = self._pickle

        def on_host(tensor: torch.Tensor, proto: int) -> Any:
            with torch._C.DisableTorchFunction():
                return pickle(tensor, proto)

        torch.Tensor._reduce_ex_internal = on_host  # type: ignore[method-assign]
        super().__enter__()
        return self

    def __exit__(self, *exc: object) -> None:
        super().__exit__(*exc)
        torch.Tensor._reduce_ex_internal = self._pickle  # type: ignore[method-assign]

    def _held(self, tensor: torch.Tensor) -> bool:
        return tensor in self._on_device

    def _mark(self, result: Any) -> Any:
        for leaf in tree_flatten(result)[0]:
            if isinstance(leaf, torch.Tensor):
                self._on_device[leaf] = True
        return result

    def __torch_function__(self, func: Any, types: Any, args: Any = (), kwargs: Any = None
                           ) -> Any:
        kwargs = kwargs or {}
        if func == torch.Tensor.device.__get__:  # a new method-wrapper each time: ==, not is
            return DEVICE if self._held(args[0]) else func(*args)
        if func is torch.Tensor.to:
            return self._to(args[0], _target(args[1:], kwargs), args, kwargs)
        if func is torch.Tensor.cpu:
            return self._to(args[0], HOST, args, kwargs)
        if func in (torch.Tensor.numpy, torch.Tensor.__array__) and self._held(args[0]):
            raise TypeError(f"can't convert {DEVICE} device type tensor to numpy. Use "
                            f"Tensor.cpu() to copy the tensor to host memory first.")
        made_there = _device_of(kwargs.get("device")) == DEVICE
        if made_there:
            kwargs = {**kwargs, "device": HOST}
        inputs = _checked_arguments(func, args, kwargs)
        tensors = [t for t in tree_flatten(inputs)[0] if isinstance(t, torch.Tensor)]
        held = [t for t in tensors if self._held(t)]
        self.checked += 1
        if held and not _across(func):
            host = [t for t in tensors if not self._held(t) and t.dim() > 0]
            if host:
                raise RuntimeError(
                    f"Expected all tensors to be on the same device, but found at least two "
                    f"devices, {DEVICE} and {HOST}! (in {getattr(func, '__name__', func)}: "
                    f"{len(held)} on the device, host shapes {[tuple(t.shape) for t in host]})")
        if func is torch.linalg.lstsq and held and kwargs.get("driver") not in (None, "gels"):
            raise RuntimeError("torch.linalg.lstsq: `driver` other than `gels` is not "
                               "supported on CUDA")
        result = func(*args, **kwargs)
        if (held and not _across(func)) or made_there:
            self._mark(result)
        return result

    def _to(self, tensor: torch.Tensor, target: torch.device | None, args: Any,
            kwargs: Any) -> torch.Tensor:
        """Tensor.to / .cpu: a parameter moves in place (as Module.to moves it), any other
        tensor is copied to the other side."""
        on_host = [HOST if _device_of(a) is not None else a for a in args[1:]]
        plain = {k: HOST if k == "device" else v for k, v in kwargs.items()}
        moved: torch.Tensor = torch.Tensor.to(tensor, *on_host, **plain)
        if target is None or (target == DEVICE) == self._held(tensor):
            return self._mark(moved) if self._held(tensor) else moved
        if isinstance(tensor, torch.nn.Parameter) and moved is tensor:
            if target == DEVICE:
                self._on_device[tensor] = True
            else:
                del self._on_device[tensor]
            return tensor
        copy = moved.clone() if moved is tensor else moved
        return self._mark(copy) if target == DEVICE else copy


def _across(func: Any) -> bool:
    return any(func == allowed for allowed in _ACROSS)  # method-wrappers compare by ==


def _checked_arguments(func: Any, args: Any, kwargs: Any) -> Any:
    """The arguments whose devices must agree: an index may stay on the host."""
    if func is torch.Tensor.__getitem__:
        return args[:1]
    if func is torch.Tensor.__setitem__:
        return (args[0], args[2])
    return (args, kwargs)


def _device_of(value: Any) -> torch.device | None:
    if isinstance(value, (str, torch.device)):
        return torch.device(value)
    return None


def _target(args: Any, kwargs: Any) -> torch.device | None:
    """The device a Tensor.to call names, if any."""
    for value in (*args, kwargs.get("device")):
        if (device := _device_of(value)) is not None:
            return device
    return None
