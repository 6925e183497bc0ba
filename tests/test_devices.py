"""dicetrace.devices: the device a batch runs on, by argument or by a use_device block (the GPU itself: tests/core/test_gpu.py)."""

from __future__ import annotations

import pytest

from dicetrace.devices import CPU, Device, DeviceError, default_device, device_label, resolve_device, use_device
from dicetrace.ics import seed_slice
from dicetrace.simulate import simulate_batch


def test_use_device_resolves_once_sets_the_default_of_every_batch_in_its_block_and_restores_it():
    """The default is the CPU; a block of ``auto`` resolves it when it starts (here, without a GPU: the CPU, said
    once) and every batch in it takes that Device; the default comes back after it."""
    from dicetrace.devices import gpu_unavailable_reason

    assert default_device() == CPU and default_device().label == "cpu" and not default_device().gpu
    with use_device("auto"):
        inside = default_device()
        assert isinstance(inside, Device)
        if gpu_unavailable_reason() is not None:
            assert inside == CPU
        with use_device("cpu"):
            assert default_device() == CPU
        assert default_device() is inside
    assert default_device() == CPU


def test_a_resolved_device_is_taken_as_it_is():
    """A Device is resolved already: resolve_device gives it back (a GPU's name is not asked again), and a name
    resolves to one."""
    fake = Device("cuda", "cuda: a GPU that is not here")
    assert resolve_device(fake) is fake and device_label(fake) == "cuda: a GPU that is not here" and fake.gpu
    assert resolve_device("cpu") == CPU and resolve_device(None) == default_device()
    assert str(fake) == fake.label


def test_a_batch_given_no_device_takes_the_blocks():
    """A block of ``cuda`` is refused where there is no GPU, when it starts (before any work); a batch that names
    the CPU runs there in any block."""
    from dicetrace.devices import gpu_unavailable_reason

    ics = seed_slice([1.0, 2.0], [3.0, 4.0])
    with use_device("cpu"):
        assert simulate_batch(ics, config="seed").device == "cpu"
    if gpu_unavailable_reason() is not None:
        with pytest.raises(DeviceError, match="device 'cuda': "):
            with use_device("cuda"):
                pass  # pragma: no cover
    else:  # pragma: no cover (a GPU machine)
        with use_device("cuda"):
            assert simulate_batch(ics, config="seed", device="cpu").device == "cpu"


def test_use_device_refuses_an_unknown_device_at_once():
    with pytest.raises(DeviceError, match="device must be one of cpu, cuda, auto, got 'gpu'"):
        with use_device("gpu"):
            pass  # pragma: no cover
    assert default_device() == CPU


def test_the_cpu_label():
    assert device_label("cpu") == "cpu" == CPU.label
