"""``python -m bench`` runs every benchmark even when one fails (issue 16), and the gimbal
benchmark retries a lost status packet as the driver does."""

import sys
import types

import pytest
from dynamixel_sdk import COMM_RX_TIMEOUT, COMM_SUCCESS

bench_main = pytest.importorskip("bench.__main__")
bench_gimbal = pytest.importorskip("bench.bench_gimbal")


def test_a_failing_benchmark_is_marked_and_the_rest_still_run(monkeypatch, capsys):
    def boom(argv):
        raise RuntimeError("status packet lost")

    def fine(argv):
        print("TABLE OF fine", argv)

    for name, fn in (("zzboom", boom), ("zzfine", fine)):
        monkeypatch.setitem(sys.modules, f"bench.bench_{name}",
                            types.SimpleNamespace(main=fn))
    monkeypatch.setattr(bench_main, "_names", lambda: ["zzboom", "zzfine"])
    assert bench_main.main(["--quick"]) == 1
    out = capsys.readouterr().out
    assert "RuntimeError: status packet lost" in out
    assert "=== bench zzboom: FAILED" in out
    assert "TABLE OF fine ['--quick']" in out
    assert out.rstrip().endswith("1 of 2 benchmark(s) FAILED: zzboom")
    monkeypatch.setattr(bench_main, "_names", lambda: ["zzfine"])
    assert bench_main.main([]) == 0


def test_a_benchmarks_argument_error_is_its_message_not_a_traceback(capsys):
    # a bench's own argparse check (bench tracker's --stream-samples) ends that bench with its
    # message and exit 2 reported, and no traceback
    assert bench_main.main(["tracker", "--stream-samples=5"]) == 1
    out, err = capsys.readouterr()
    assert "--stream-samples must be at least 100" in err
    assert "Traceback" not in out + err
    assert "=== bench tracker: FAILED (bad arguments, exit 2) ===" in out


class FlakySyncRead:
    """A GroupSyncRead whose status packets are lost on the listed calls."""

    def __init__(self, lose):
        self.lose, self.calls = set(lose), 0

    def addParam(self, i):
        return True

    def txRxPacket(self):
        self.calls += 1
        return COMM_RX_TIMEOUT if self.calls in self.lose else COMM_SUCCESS


def test_gimbal_bench_retries_and_counts_lost_packets(monkeypatch):
    flaky = FlakySyncRead(lose={2, 5, 6})
    monkeypatch.setattr(bench_gimbal, "GroupSyncRead", lambda *a: flaky)
    assert bench_gimbal._sync_reads(object(), 4, "motion") == 3
    assert flaky.calls == 7
    attempts = bench_gimbal.RETRIES + 1
    dead = FlakySyncRead(lose=range(1, 100))
    monkeypatch.setattr(bench_gimbal, "GroupSyncRead", lambda *a: dead)
    with pytest.raises(RuntimeError, match=f"failed {attempts} times"):
        bench_gimbal._sync_reads(object(), 4, "motion")
