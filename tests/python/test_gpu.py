# tests/python/test_gpu.py — the CUDA backend from Python: the state in
# device memory without a copy (__cuda_array_interface__, DLPack), writes
# through it, and the same bits as the CPU backend.
import numpy as np
import pytest

import marbles

pytestmark = pytest.mark.gpu


def test_device_arrays_are_the_step_memory(pile):
    sim = marbles.Simulation.from_dict(pile, backend="cuda")
    assert sim.backend == "cuda"
    x = sim.positions
    assert isinstance(x, marbles.DeviceArray) and x.shape == (len(sim), 3)
    cai = x.__cuda_array_interface__
    assert cai["typestr"] == "<f4" and cai["data"][1] is False and cai["data"][0] != 0
    assert sim.radii.__cuda_array_interface__["data"][1] is True
    sim.step(3)
    assert sim.positions.__cuda_array_interface__["data"][0] == cai["data"][0]  # the same memory
    assert x.__dlpack_device__()[0] == 2  # kDLCUDA


def test_gpu_equals_cpu_bit_for_bit(pile):
    gpu = marbles.Simulation.from_dict(pile, backend="cuda")
    cpu = marbles.Simulation.from_dict(pile, backend="cpu")
    for s in (gpu, cpu):
        s.step(40)
    assert np.array_equal(gpu.positions.numpy(), cpu.positions)
    assert np.array_equal(gpu.angular_velocities.numpy(), cpu.angular_velocities)
    assert gpu.kinetic_energy() == cpu.kinetic_energy()


def test_writes_through_torch_change_the_next_step(pile):
    torch = pytest.importorskip("torch")
    gpu = marbles.Simulation.from_dict(pile, backend="cuda")
    cpu = marbles.Simulation.from_dict(pile, backend="cpu")
    for s in (gpu, cpu):
        s.step(5)
    v = torch.from_dlpack(gpu.velocities)
    assert v.is_cuda and v.data_ptr() == gpu.velocities.__cuda_array_interface__["data"][0]
    v[7, 2] += 1.5                      # on the device, in place
    cpu.velocities[7, 2] += np.float32(1.5)
    for s in (gpu, cpu):
        s.step(5)
    assert np.array_equal(gpu.positions.numpy(), cpu.positions)
    v[3, 0] = float("nan")
    with pytest.raises(ValueError, match=r"velocities\[3\]"):
        gpu.step()


def test_cupy_sees_the_device_memory(pile):
    cupy = pytest.importorskip("cupy")
    gpu = marbles.Simulation.from_dict(pile, backend="cuda")
    x = cupy.asarray(gpu.positions)
    assert x.data.ptr == gpu.positions.__cuda_array_interface__["data"][0]


def test_pairs_on_the_gpu_equal_the_cpu():
    rng = np.random.default_rng(3)
    xyzr = np.column_stack([rng.uniform(0, 1, (5000, 3)), rng.uniform(0.002, 0.02, 5000)]).astype(np.float32)
    assert np.array_equal(marbles.pairs(xyzr, backend="cuda"), marbles.pairs(xyzr, backend="cpu"))


def test_assignment_and_restart_with_device_arrays_out(pile, tmp_path):
    gpu = marbles.Simulation.from_dict(pile, backend="cuda")
    cpu = marbles.Simulation.from_dict(pile, backend="cpu")
    held = gpu.positions  # device arrays out: host edits must still reach the step
    for s in (gpu, cpu):
        s.step(5)
    v = cpu.velocities.copy()
    v[3] += np.float32([0, 0, 1])
    gpu.velocities = v
    cpu.velocities = v
    gpu.angular_velocities = gpu.angular_velocities  # a marbles.DeviceArray assigned: its host copy, unchanged
    cpu.checkpoint(tmp_path / "c.mck")
    for s in (gpu, cpu):
        s.step(5)
    assert np.array_equal(held.numpy(), cpu.positions)
    again = marbles.Simulation.restart(tmp_path / "c.mck", backend="cuda")
    out = again.positions
    again.step(5)
    assert np.array_equal(out.numpy(), cpu.positions)
