"""Compiled kernels are compiled once per install and never on a live clock: the one line
a first run prints, `samba warmup`, and the numpy switch."""

from __future__ import annotations

import io
import threading
import time
from pathlib import Path
from types import SimpleNamespace

import pytest

from samba.base import KernelSet, kernels_enabled
from samba.cli import main


def fake_kernel(index: Path) -> SimpleNamespace:
    """Something shaped like a numba dispatcher whose cache index is `index`."""
    return SimpleNamespace(_cache=SimpleNamespace(_cache_file=SimpleNamespace(_index_path=index)))


@pytest.mark.skipif(not kernels_enabled(), reason="numba kernels are off")
def test_a_first_run_says_it_compiles_once_and_later_runs_say_nothing(tmp_path: Path) -> None:
    calls = []
    index = tmp_path / "kernel.nbi"
    kernels = KernelSet("test", [fake_kernel(index)], [lambda: calls.append(1)], estimate_s=7.0)
    out = io.StringIO()
    assert kernels.warm_up(out) >= 0.0
    assert out.getvalue() == "samba: compiling test kernels, once: ~7 s\n" and calls == [1]
    assert kernels.warm_up(out) == 0.0 and calls == [1]  # once per process
    index.write_bytes(b"")
    again = KernelSet("test", [fake_kernel(index)], [lambda: calls.append(2)], estimate_s=7.0)
    quiet = io.StringIO()
    again.warm_up(quiet)
    assert quiet.getvalue() == "" and calls == [1, 2]


@pytest.mark.skipif(not kernels_enabled(), reason="numba kernels are off")
def test_threads_warming_one_set_together_compile_it_once(tmp_path: Path) -> None:
    calls = []
    entered = threading.Event()

    def slow_compile() -> None:
        entered.set()
        time.sleep(0.2)
        calls.append(1)

    kernels = KernelSet("test", [fake_kernel(tmp_path / "k.nbi")], [slow_compile], 7.0)
    out = io.StringIO()
    first = threading.Thread(target=kernels.warm_up, args=(out,))
    first.start()
    assert entered.wait(30.0)
    kernels.warm_up(out)  # waits for the first thread's compile
    first.join()
    assert calls == [1] and kernels.warmed
    assert out.getvalue() == "samba: compiling test kernels, once: ~7 s\n"


def test_numpy_switch_turns_every_kernel_off(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setenv("SAMBA_KERNELS", "numpy")
    assert not kernels_enabled()
    calls = []
    KernelSet("test", [], [lambda: calls.append(1)], estimate_s=1.0).warm_up()
    assert calls == []
    assert main(["warmup"]) == 0
    assert "compiled kernels are off" in capsys.readouterr().out


@pytest.mark.skipif(not kernels_enabled(), reason="numba kernels are off")
def test_warmup_loads_or_compiles_every_kernel_set(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["warmup"]) == 0
    lines = capsys.readouterr().out.splitlines()
    finished = [line for line in lines if " kernels " in line and line.endswith(" s")]
    assert [line.split(" kernels ")[0] for line in finished] == [
        "reconstruction",
        "pose index",
        "BVH reader",
    ]
