"""Bad files and arguments give one clear line and exit code 2; outputs are atomic.

Every case runs ``clusterfilter.cli.main([...])`` in-process and checks: exit code 2,
exactly one line on stderr of the form ``clusterfilter <command>: error: ...`` that
names the culprit (file, folder, topic, parameter or option), and no traceback. A few
run the installed ``clusterfilter`` executable as a subprocess, and ``--debug`` shows
the traceback. The atomicity tests interrupt a write (Ctrl-C / disk full in-process,
SIGTERM / SIGKILL to a child process) and check no half-written output is left.
"""

from __future__ import annotations

import contextlib
import errno
import io
import os
import shutil
import signal
import subprocess
import sys
import time
import zlib
from pathlib import Path

import numpy as np
import pytest

from clusterfilter_ros.cli import main
from clusterfilter_ros.core.frame import AVIA, MID360, Frame, Sequence, TimedPositions
from clusterfilter_ros.errors import InputError
from clusterfilter_ros.io.dataset import write_output

CLI = Path(sys.executable).with_name("clusterfilter")


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Inputs good and bad: a sequence folder, bags, and broken copies of them."""
    root = tmp_path_factory.mktemp("cli_errors")
    rng = np.random.default_rng(0)
    frames = [
        Frame(100 + 0.1 * i + (0.01 if s == AVIA else 0.0), s, rng.normal(0, 10, (200, 3)))
        for i in range(20)
        for s in (MID360, AVIA)
    ]
    seq = Sequence("s", frames, TimedPositions(np.arange(100, 102, 0.1), rng.normal(0, 1, (20, 3))))
    write_output(seq, root / "seq", "mmaud")
    write_output(seq, root / "bag2", "rosbag2")
    write_output(seq, root / "b1.bag", "rosbag1")
    write_output(seq, root / "bagm", "rosbag2", storage="mcap")
    write_output(seq, root / "custom.bag", "rosbag1", lidar_msg="CustomMsg")
    (root / "empty").mkdir()
    (root / "dir.npz").mkdir()
    (root / "file.txt").write_text("not a folder\n")

    def broken_copy(name: str, damage) -> None:
        folder = root / name
        shutil.copytree(root / "seq", folder)
        damage(sorted((folder / "lidar_360").iterdir())[3])

    broken_copy("corrupt", lambda f: f.write_bytes(b"garbage" * 10))
    broken_copy("trunc", lambda f: f.write_bytes(f.read_bytes()[:500]))
    broken_copy("shape", lambda f: np.save(f, np.zeros((5, 2))))
    broken_copy("shape1d", lambda f: np.save(f, np.zeros(7)))
    broken_copy("strings", lambda f: np.save(f, np.array([["a", "b", "c"]])))
    broken_copy(
        "pickled", lambda f: np.save(f, np.array([{"a": 1}], dtype=object), allow_pickle=True)
    )
    broken_copy("badname", lambda f: shutil.copy(f, f.with_name("hello.npy")))
    broken_copy("nsname", lambda f: shutil.copy(f, f.with_name("1706255599999223000.npy")))
    shutil.copytree(root / "seq", root / "gtbad")
    np.save(sorted((root / "gtbad" / "ground_truth").iterdir())[2], np.zeros((2, 2)))
    (root / "emptyseq" / "lidar_360").mkdir(parents=True)
    shutil.copytree(root / "bag2", root / "bag2t")
    db = next((root / "bag2t").glob("*.db3"))
    db.write_bytes(db.read_bytes()[: db.stat().st_size // 2])
    raw = (root / "b1.bag").read_bytes()
    (root / "b1t.bag").write_bytes(raw[: len(raw) // 2])
    (root / "b1z.bag").write_bytes(b"")
    shutil.copytree(root / "bagm", root / "bagmt")
    mcap = next((root / "bagmt").glob("*.mcap"))
    mcap.write_bytes(mcap.read_bytes()[: mcap.stat().st_size // 2])
    np.save(root / "single.npy", np.zeros((3, 3)))
    (root / "pred.csv").write_text("timestamp,x,y,z\n100.0,1,2,3\n100.1,1,2,3\n")
    (root / "wrong_header.csv").write_text("a,b\n1,2\n")
    (root / "ragged.csv").write_text("timestamp,x,y,z\n100.0,1,2\n")
    (root / "text_value.csv").write_text("timestamp,x,y,z\n100.0,1,2,zz\n")
    (root / "nan_stamp.csv").write_text("timestamp,x,y,z\n100.0,1,2,3\nnan,1,2,3\n")
    (root / "stamps_inf.txt").write_text("timestamp\n100.0\ninf\n100.2\n")
    (root / "binary.csv").write_bytes(b"\xff\xfe\x00garbage\x00\x01")
    (root / "huge_field.csv").write_text(
        "timestamp,x,y,z\n100.0,1,2,3\n" + "1" * 200_000 + ",1,2,3\n"
    )
    return root


# (id, argv, text the error line must contain). {R}: shared inputs, {T}: per-test folder.
CASES = [
    # detect
    ("detect-missing-input", "detect {R}/nope -o {T}/o.csv", "{R}/nope"),
    ("detect-empty-folder", "detect {R}/empty -o {T}/o.csv", "{R}/empty"),
    ("detect-no-lidar-files", "detect {R}/emptyseq -o {T}/o.csv", "{R}/emptyseq: no lidar"),
    ("detect-corrupt-npy", "detect {R}/corrupt -o {T}/o.csv", "{R}/corrupt/lidar_360/"),
    ("detect-truncated-npy", "detect {R}/trunc -o {T}/o.csv", "{R}/trunc/lidar_360/"),
    ("detect-npy-shape-5x2", "detect {R}/shape -o {T}/o.csv", "found shape (5, 2)"),
    ("detect-npy-1d", "detect {R}/shape1d -o {T}/o.csv", "found shape (7,)"),
    ("detect-npy-strings", "detect {R}/strings -o {T}/o.csv", "{R}/strings/lidar_360/"),
    ("detect-npy-pickled", "detect {R}/pickled -o {T}/o.csv", "{R}/pickled/lidar_360/"),
    ("detect-npy-bad-name", "detect {R}/badname -o {T}/o.csv", "hello.npy"),
    ("detect-npy-name-in-ns", "detect {R}/nsname -o {T}/o.csv", "1706255599999223000.npy"),
    ("detect-single-npy", "detect {R}/single.npy -o {T}/o.csv", "{R}/single.npy"),
    ("detect-unknown-file-type", "detect {R}/file.txt -o {T}/o.csv", "{R}/file.txt"),
    ("detect-truncated-rosbag2", "detect {R}/bag2t -o {T}/o.csv", "{R}/bag2t"),
    ("detect-truncated-rosbag1", "detect {R}/b1t.bag -o {T}/o.csv", "{R}/b1t.bag"),
    ("detect-empty-rosbag1", "detect {R}/b1z.bag -o {T}/o.csv", "{R}/b1z.bag"),
    ("detect-truncated-mcap", "detect {R}/bagmt -o {T}/o.csv", "{R}/bagmt"),
    ("detect-output-is-folder", "detect {R}/seq -o {T}", "cannot write {T}"),
    ("detect-output-under-file", "detect {R}/seq -o {R}/file.txt/o.csv", "{R}/file.txt is a file"),
    ("detect-missing-timestamps", "detect {R}/seq -o {T}/o.csv --timestamps {R}/no.txt", "no.txt"),
    (
        "detect-timestamps-inf",
        "detect {R}/seq -o {T}/o.csv --timestamps {R}/stamps_inf.txt",
        "{R}/stamps_inf.txt: line 3",
    ),
    (
        "detect-timestamps-nan",
        "detect {R}/seq -o {T}/o.csv --timestamps {R}/nan_stamp.csv",
        "{R}/nan_stamp.csv: line 3",
    ),
    ("detect-max-gap-nan", "detect {R}/seq -o {T}/o.csv --max-gap nan", "--max-gap"),
    ("detect-max-gap-negative", "detect {R}/seq -o {T}/o.csv --max-gap -1", "--max-gap"),
    (
        "detect-timestamps-huge-field",
        "detect {R}/seq -o {T}/o.csv --timestamps {R}/huge_field.csv",
        "{R}/huge_field.csv: line 3",
    ),
    (
        "detect-binary-params-file",
        "detect {R}/seq -o {T}/o.csv --params-file {R}/binary.csv",
        "{R}/binary.csv",
    ),
    (
        "detect-missing-params-file",
        "detect {R}/seq -o {T}/o.csv --params-file {R}/no.yaml",
        "{R}/no.yaml",
    ),
    ("detect-param-out-of-range", "detect {R}/seq -o {T}/o.csv --param eps=-1", "'eps'"),
    ("detect-param-unknown", "detect {R}/seq -o {T}/o.csv --param nope=1", "'nope'"),
    ("detect-param-nan", "detect {R}/seq -o {T}/o.csv --param eps=nan", "'eps'"),
    ("detect-unknown-topic", "detect {R}/bag2 -o {T}/o.csv --topic /nope=avia", "/nope"),
    ("detect-bad-topic-syntax", "detect {R}/b1.bag -o {T}/o.csv --topic nope", "nope"),
    ("detect-topic-on-folder", "detect {R}/seq -o {T}/o.csv --topic /a=avia", "{R}/seq"),
    ("detect-unknown-sensor", "detect {R}/seq -o {T}/o.csv --sensors lidarX", "lidarX"),
    ("detect-topic-unknown-sensor", "detect {R}/bag2 -o {T}/o.csv --topic /a=lidarX", "lidarX"),
    # evaluate
    ("evaluate-missing-pred", "evaluate {R}/nope.csv {R}/seq", "{R}/nope.csv"),
    ("evaluate-pred-header", "evaluate {R}/wrong_header.csv {R}/seq", "{R}/wrong_header.csv"),
    ("evaluate-pred-ragged", "evaluate {R}/ragged.csv {R}/seq", "{R}/ragged.csv: line 2"),
    ("evaluate-pred-text", "evaluate {R}/text_value.csv {R}/seq", "{R}/text_value.csv"),
    ("evaluate-pred-nan-stamp", "evaluate {R}/nan_stamp.csv {R}/seq", "{R}/nan_stamp.csv: line 3"),
    ("evaluate-pred-binary", "evaluate {R}/binary.csv {R}/seq", "{R}/binary.csv"),
    (
        "evaluate-pred-huge-field",
        "evaluate {R}/huge_field.csv {R}/seq",
        "{R}/huge_field.csv: line 3",
    ),
    ("evaluate-pred-folder", "evaluate {R}/empty {R}/seq", "{R}/empty"),
    ("evaluate-missing-gt", "evaluate {R}/pred.csv {R}/nope", "{R}/nope"),
    ("evaluate-empty-gt-folder", "evaluate {R}/pred.csv {R}/empty", "{R}/empty"),
    ("evaluate-gt-npy-shape", "evaluate {R}/pred.csv {R}/gtbad", "{R}/gtbad/ground_truth/"),
    ("evaluate-plot-into-folder", "evaluate {R}/pred.csv {R}/seq --plot {T}", "cannot write {T}"),
    ("evaluate-max-gap-nan", "evaluate {R}/pred.csv {R}/seq --max-gap nan", "--max-gap"),
    ("evaluate-hit-radius-neg", "evaluate {R}/pred.csv {R}/seq --hit-radius -1", "--hit-radius"),
    ("evaluate-unknown-gt-topic", "evaluate {R}/pred.csv {R}/bag2 --ground-truth-topic /gt", "/gt"),
    ("evaluate-truncated-gt-bag", "evaluate {R}/pred.csv {R}/b1t.bag", "{R}/b1t.bag"),
    (
        "evaluate-gt-topic-not-bag",
        "evaluate {R}/pred.csv {R}/seq --ground-truth-topic /gt",
        "--ground-truth-topic",
    ),
    # convert
    ("convert-missing-input", "convert {R}/nope {T}/out --to mmaud", "{R}/nope"),
    ("convert-output-exists", "convert {R}/seq {R}/bag2 --to mmaud", "{R}/bag2"),
    (
        "convert-unknown-topic-rosbag2",
        "convert {R}/bag2 {T}/out --to mmaud --topic /nope=avia",
        "/nope",
    ),
    (
        "convert-unknown-topic-rosbag1",
        "convert {R}/b1.bag {T}/out --to mmaud --topic /nope=avia",
        "/nope",
    ),
    (
        "convert-unknown-gt-topic",
        "convert {R}/bag2 {T}/out --to mmaud --ground-truth-topic /gt",
        "/gt",
    ),
    ("convert-bad-topic-syntax", "convert {R}/bag2 {T}/out --to mmaud --topic nope", "nope"),
    ("convert-truncated-rosbag1", "convert {R}/b1t.bag {T}/out --to rosbag2", "{R}/b1t.bag"),
    (
        "convert-output-under-file",
        "convert {R}/seq {R}/file.txt/out --to mmaud",
        "{R}/file.txt is a file",
    ),
    ("convert-unknown-sensor", "convert {R}/seq {T}/out --to mmaud --sensors lidarX", "lidarX"),
    ("convert-no-lidar-files", "convert {R}/emptyseq {T}/out --to rosbag2", "{R}/emptyseq"),
    ("convert-truncated-npy", "convert {R}/trunc {T}/out.bag --to rosbag1", "{R}/trunc/lidar_360/"),
    # info
    ("info-missing-input", "info {R}/nope", "{R}/nope"),
    ("info-empty-folder", "info {R}/empty", "{R}/empty"),
    ("info-truncated-mcap", "info {R}/bagmt", "{R}/bagmt"),
    ("info-unknown-topic-mcap", "info {R}/bagm --topic /nope=avia", "/nope"),
    ("info-corrupt-npy", "info {R}/corrupt", "{R}/corrupt/lidar_360/"),
    # simulate
    ("simulate-unknown-scenario", "simulate {T}/sim --scenario nope", "'nope'"),
    ("simulate-unknown-drone", "simulate {T}/sim --drone nope --duration 1", "'nope'"),
    ("simulate-duration-nan", "simulate {T}/sim --duration nan", "duration"),
    ("simulate-duration-negative", "simulate {T}/sim --duration -1", "duration"),
    ("simulate-output-exists", "simulate {R}/seq --duration 1", "{R}/seq"),
    (
        "simulate-output-under-file",
        "simulate {R}/file.txt/sim --duration 0.3",
        "{R}/file.txt is a file",
    ),
    ("simulate-preview-suffix", "simulate {T}/sim --duration 0.3 --preview {T}/p.txt", "p.txt"),
    # replay (all fail before any rclpy context is created)
    ("replay-missing-input", "replay {R}/nope", "{R}/nope"),
    ("replay-empty-folder", "replay {R}/empty", "{R}/empty"),
    ("replay-no-lidar-files", "replay {R}/emptyseq", "{R}/emptyseq"),
    ("replay-truncated-bag", "replay {R}/b1t.bag", "{R}/b1t.bag"),
    ("replay-unknown-topic", "replay {R}/bag2 --topic /nope=avia", "/nope"),
    ("replay-rate-nan", "replay {R}/seq --rate nan", "--rate"),
    ("replay-missing-gt", "replay {R}/seq --ground-truth {R}/nope.csv", "{R}/nope.csv"),
]
_QUIET = {"detect", "convert", "simulate"}  # commands with a progress bar to silence


def _run_in_process(argv: list[str]) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(argv)
    return code, out.getvalue(), err.getvalue()


@pytest.mark.parametrize(("argv", "culprit"), [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_error_is_one_line_naming_the_culprit(
    files: Path, tmp_path: Path, argv: str, culprit: str
) -> None:
    fill = {"R": str(files), "T": str(tmp_path)}
    args = [a.format(**fill) for a in argv.split()]
    if args[0] in _QUIET:
        args.append("--quiet")
    code, out, err = _run_in_process(args)
    lines = err.strip().splitlines()
    assert code == 2, (code, err)
    assert len(lines) == 1, err
    assert lines[0].startswith(f"clusterfilter {args[0]}: error: "), lines[0]
    assert culprit.format(**fill) in lines[0]
    assert "Traceback" not in err + out
    assert not list(tmp_path.glob(".*tmp*")), "temporary files left behind"


def test_simulate_checks_its_extra_outputs_before_writing_the_sequence(
    files: Path, tmp_path: Path
) -> None:
    out = tmp_path / "sim"
    code, _, err = _run_in_process(
        ["simulate", str(out), "--duration", "0.3", "--truth", str(files / "dir.npz"), "--quiet"]
    )
    assert code == 2
    assert f"cannot write {files / 'dir.npz'}: it is a folder" in err
    assert not out.exists()  # nothing half-done: the sequence was not written either


@pytest.mark.parametrize("bag", ["b1.bag", "bag2", "bagm", "custom.bag"])
def test_bit_flipped_bags_read_or_fail_cleanly(
    files: Path, tmp_path: Path, bag: str, capsys: pytest.CaptureFixture[str]
) -> None:
    """1-5 random bit flips anywhere in a bag (header, index, message data), 12 times
    per format: ``info`` and ``convert`` either succeed or give the one-line error."""
    rng = np.random.default_rng(zlib.crc32(bag.encode()))
    copy = tmp_path / bag
    (shutil.copytree if (files / bag).is_dir() else shutil.copy)(files / bag, copy)
    target = copy if copy.is_file() else next(p for p in copy.iterdir() if p.suffix != ".yaml")
    original = target.read_bytes()
    outcomes = {0: 0, 2: 0}
    for trial in range(12):
        data = bytearray(original)
        for _ in range(int(rng.integers(1, 6))):
            data[int(rng.integers(0, len(data)))] ^= 1 << int(rng.integers(0, 8))
        target.write_bytes(bytes(data))
        out = tmp_path / f"out{trial}"
        for argv in (["info", str(copy)], ["convert", str(copy), str(out), "--to", "mmaud"]):
            code, _, err = _run_in_process(argv + (["--quiet"] if argv[0] == "convert" else []))
            assert code in (0, 2), err
            if code == 2:
                lines = err.strip().splitlines()
                assert len(lines) == 1 and lines[0].startswith(f"clusterfilter {argv[0]}: error:")
                assert "Traceback" not in err
            outcomes[code] += 1
    with capsys.disabled():
        print(
            f"\n[cli] {bag} with bit flips: {outcomes[0]} runs read it, "
            f"{outcomes[2]} one-line errors"
        )


def test_every_command_has_error_cases(capsys: pytest.CaptureFixture[str]) -> None:
    commands = {c[1].split()[0] for c in CASES}
    assert commands == {"detect", "evaluate", "convert", "info", "simulate", "replay"}
    with capsys.disabled():
        print(f"\n[cli] {len(CASES)} bad-input cases over {len(commands)} commands")


def test_debug_raises_the_exception(files: Path, tmp_path: Path) -> None:
    with pytest.raises(InputError, match="no such file"):
        main(["--debug", "detect", str(files / "nope"), "-o", str(tmp_path / "o.csv")])


def test_subprocess_error_line_and_debug_traceback(files: Path, tmp_path: Path) -> None:
    argv = [str(CLI), "detect", str(files / "corrupt"), "-o", str(tmp_path / "o.csv"), "--quiet"]
    plain = subprocess.run(argv, capture_output=True, text=True, timeout=120)
    assert plain.returncode == 2
    assert plain.stderr.count("\n") == 1 and "Traceback" not in plain.stderr
    assert str(files / "corrupt" / "lidar_360") in plain.stderr
    debug = subprocess.run(
        [argv[0], "--debug", *argv[1:]], capture_output=True, text=True, timeout=120
    )
    assert debug.returncode != 0
    assert "Traceback" in debug.stderr and "InputError" in debug.stderr
    assert not (tmp_path / "o.csv").exists()


# ----------------------------------------------------------------------------- atomicity
def _half_then(exc: BaseException):
    """A ``Path.write_text`` that writes half of the text, then fails with ``exc``."""

    def write_text(self: Path, data: str, *args, **kwargs) -> int:
        with open(self, "w", encoding="utf-8") as fh:
            fh.write(data[: len(data) // 2])
        raise exc

    return write_text


@pytest.mark.parametrize(
    ("failure", "expected_code"),
    [
        (KeyboardInterrupt(), 130),
        (OSError(errno.ENOSPC, "No space left on device"), 2),
    ],
    ids=["ctrl-c", "disk-full"],
)
def test_interrupted_csv_write_leaves_the_old_file(
    files: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, failure, expected_code
) -> None:
    """detect is interrupted half-way through writing its CSV: the previous CSV stays
    byte for byte and no temporary file is left next to it."""
    out = tmp_path / "estimates.csv"
    out.write_text("timestamp,x,y,z\n1.0,2.0,3.0,4.0\n")
    before = out.read_bytes()
    monkeypatch.setattr(Path, "write_text", _half_then(failure))
    code, _, err = _run_in_process(["detect", str(files / "seq"), "-o", str(out), "--quiet"])
    monkeypatch.undo()
    assert code == expected_code, err
    if expected_code == 2:
        assert err.strip().splitlines() == [
            f"clusterfilter detect: error: cannot write {out}: No space left on device"
        ]
    assert out.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["estimates.csv"]


def _start_simulation(out: Path, env: dict[str, str]) -> subprocess.Popen:
    return subprocess.Popen(
        [str(CLI), "simulate", str(out), "--duration", "60", "--quiet"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )


def _wait_for_partial_output(folder: Path, proc: subprocess.Popen, timeout: float = 60) -> Path:
    """The temporary folder of a running writer, once it holds a few frames."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and proc.poll() is None:
        for tmp in folder.glob(".sim.*.tmp"):
            if len(list(tmp.rglob("*.npy"))) >= 6:
                return tmp
        time.sleep(0.05)
    pytest.fail(f"simulate did not start writing (rc={proc.poll()})")


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGKILL], ids=["SIGTERM", "SIGKILL"])
def test_killed_writer_leaves_no_partial_output(tmp_path: Path, sig: signal.Signals) -> None:
    """``simulate`` killed while writing its sequence folder: no OUT folder appears.
    SIGTERM also removes the temporary folder; after SIGKILL (nothing can run) only a
    hidden ``.sim.*.tmp`` folder remains, never a half-written ``sim``."""
    out = tmp_path / "sim"
    proc = _start_simulation(out, dict(os.environ))
    try:
        _wait_for_partial_output(tmp_path, proc)
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert not out.exists()
    leftovers = [p.name for p in tmp_path.iterdir()]
    if sig == signal.SIGTERM:
        assert proc.returncode == 130, err
        assert "Traceback" not in err and err.strip().endswith("interrupted")
        assert leftovers == []
    else:
        assert proc.returncode == -signal.SIGKILL
        assert all(name.startswith(".sim.") and name.endswith(".tmp") for name in leftovers)


def test_sigterm_caught_inside_a_library_call_is_still_an_interruption(monkeypatch, capsys):
    """SIGTERM raises KeyboardInterrupt wherever the main thread is; numpy's ``tofile``
    catches it and raises a TypeError instead (seen once in the killed-writer test on
    CPython 3.12). The command still reports an interruption (130), without a traceback."""
    from clusterfilter_ros.cli import info

    def run_swallowing_the_interrupt(args):
        try:
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(5.0)  # the handler raises here
        except KeyboardInterrupt:
            pass
        raise TypeError("expected str, bytes or os.PathLike object, not BufferedWriter")

    def run_failing(args):
        raise TypeError("bug")

    previous = signal.signal(signal.SIGTERM, signal.SIG_DFL)
    try:
        monkeypatch.setattr(info, "run", run_swallowing_the_interrupt)
        assert main(["info", "anything"]) == 130
        assert capsys.readouterr().err.strip() == "clusterfilter info: interrupted"
        # Without SIGTERM the same error is a bug and propagates.
        monkeypatch.setattr(info, "run", run_failing)
        with pytest.raises(TypeError):
            main(["info", "anything"])
    finally:
        signal.signal(signal.SIGTERM, previous)
