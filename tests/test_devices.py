"""dicetrace.devices: the device a batch runs on, by argument or by a use_device block (the GPU itself: tests/core/test_gpu.py)."""

from __future__ import annotations

import pytest

from dicetrace.devices import DeviceError, default_device, device_label, use_device
from dicetrace.ics import seed_slice
from dicetrace.simulate import simulate_batch


def test_use_device_sets_the_default_of_every_batch_in_its_block_and_restores_it():
    assert default_device() == "cpu"
    with use_device("auto"):
        assert default_device() == "auto"
        with use_device("cpu"):
            assert default_device() == "cpu"
        assert default_device() == "auto"
    assert default_device() == "cpu"


def test_a_batch_given_no_device_takes_the_blocks():
    """A block of ``cuda`` reaches a batch that names no device (refused here where there is no GPU, before any
    work); one that names the CPU runs there."""
    from dicetrace.devices import gpu_unavailable_reason

    ics = seed_slice([1.0, 2.0], [3.0, 4.0])
    with use_device("cuda"):
        assert simulate_batch(ics, config="seed", device="cpu").device == "cpu"
        if gpu_unavailable_reason() is not None:
            with pytest.raises(DeviceError, match="device 'cuda': "):
                simulate_batch(ics, config="seed")


def test_use_device_refuses_an_unknown_device_at_once():
    with pytest.raises(DeviceError, match="device must be one of cpu, cuda, auto, got 'gpu'"):
        with use_device("gpu"):
            pass  # pragma: no cover
    assert default_device() == "cpu"


def test_the_cpu_label():
    assert device_label("cpu") == "cpu"
