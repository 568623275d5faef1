"""The console-script entry (crackbake.entry): one line and exit 2 off Linux, the command on it."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from crackbake.entry import bakes, numba_skips_coverage, platform_error, quiet_blas

ROOT = Path(__file__).resolve().parents[1]


def _run(code: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          env=env, timeout=120)


def test_other_systems_get_one_line_and_exit_2():
    for platform in ("win32", "darwin", "cygwin"):
        msg = platform_error(platform)
        assert msg and "Linux" in msg and platform in msg and "\n" not in msg
    # A whole process that believes it is on Windows: no traceback, nothing imported.
    r = _run("import sys; sys.platform = 'win32'; from crackbake.entry import main; main()")
    assert r.returncode == 2, r.stderr
    assert r.stderr.count("\n") == 1 and "runs on Linux only" in r.stderr, r.stderr
    assert "Traceback" not in r.stderr


def test_linux_runs_the_command():
    assert platform_error("linux") is None
    r = _run("import sys; sys.argv = ['crackbake', '--version']; "
             "from crackbake.entry import main; main()")
    assert r.returncode == 0, r.stderr
    assert "crackbake" in r.stdout


def test_the_exit_skips_teardown_but_keeps_what_an_exit_owes(tmp_path):
    """The command's end: exit status as SystemExit's, atexit handlers run, non-daemon threads
    joined, buffered output flushed; only the interpreter's teardown is skipped."""
    flag = tmp_path / "thread-done"
    code = (
        "import atexit, sys, threading, time\n"
        "atexit.register(lambda: print('atexit ran'))\n"
        f"threading.Thread(target=lambda: (time.sleep(0.3), open({str(flag)!r}, 'w').close()))"
        ".start()\n"
        "sys.argv = ['crackbake', '--help']\n"
        "sys.stdout.write('buffered, no newline')\n"
        "from crackbake.entry import main; main()\n"
        "print('not reached')\n"
    )
    r = _run(code)
    assert r.returncode == 0, r.stderr
    assert "Usage:" in r.stdout and "buffered, no newline" in r.stdout
    assert "atexit ran" in r.stdout and "not reached" not in r.stdout
    assert flag.exists()  # the thread was joined, not killed
    # A failing command keeps its status (click's usage error: 2).
    r = _run("import sys; sys.argv = ['crackbake', '--no-such-option']; "
             "from crackbake.entry import main; main()")
    assert r.returncode == 2 and "no-such-option" in r.stderr


def test_the_exit_is_pythons_own_under_a_profiler():
    """A profiler writes its results after the command returns: no os._exit under one."""
    r = _run("import sys, cProfile; sys.argv = ['crackbake', '--help']\n"
             "from crackbake.entry import main\n"
             "p = cProfile.Profile(); p.enable()\n"
             "try:\n    main()\nexcept SystemExit as e:\n    p.disable(); print('exit', e.code)\n")
    assert r.returncode == 0, r.stderr
    assert "exit 0" in r.stdout


def test_quiet_blas_keeps_a_users_choice():
    env: dict[str, str] = {}
    quiet_blas(env)
    assert env == {"OPENBLAS_NUM_THREADS": "1"}
    for chosen in ({"OPENBLAS_NUM_THREADS": "8"}, {"OMP_NUM_THREADS": "4"}):
        env = dict(chosen)
        quiet_blas(env)
        assert env == chosen


@pytest.mark.skipif(os.cpu_count() < 2, reason="OpenBLAS starts no threads on one core")
def test_numpy_after_quiet_blas_starts_no_blas_threads():
    # Threads of a fresh interpreter once numpy is imported (its import calls BLAS): OpenBLAS
    # starts one per core unless told otherwise, and none after quiet_blas.
    code = ("import os, sys; from crackbake.entry import quiet_blas; "
            "sys.argv[1:] == ['quiet'] and quiet_blas(); import numpy; "
            "print(len(os.listdir('/proc/self/task')))")
    env = {k: v for k, v in os.environ.items()
           if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")}
    env["PYTHONPATH"] = str(ROOT)

    def threads(*args: str) -> int:
        out = subprocess.run([sys.executable, "-c", code, *args], env=env, text=True,
                             capture_output=True, check=True).stdout
        return int(out)

    assert threads("quiet") == 1
    assert threads() > 1


def _numba_and_coverage(tmp_path: Path, skip: bool, env: dict | None = None) -> list[str]:
    """In a fresh interpreter with a package named ``coverage`` on its path (a stand-in for
    coverage.py, which this environment may not have): numba's view of it, then whether any
    other import still gets it."""
    package = tmp_path / "coverage"
    package.mkdir(exist_ok=True)
    # what numba's hook reads of it: Coverage.current(), and coverage.types for its annotations
    (package / "__init__.py").write_text(
        "from . import types\nclass Coverage:\n    current = staticmethod(lambda: None)\n")
    (package / "types.py").write_text("class Tracer:\n    pass\ndef __getattr__(name):\n"
                                      "    return object\n")
    code = ("import sys; from crackbake.entry import numba_skips_coverage; "
            f"print(numba_skips_coverage() if {skip} else 'not asked'); "
            "import numba.misc.coverage_support as c; print(c.coverage_available); "
            "print('coverage' in sys.modules); import coverage; print(coverage.__file__)")
    base = {k: v for k, v in os.environ.items() if k != "NUMBA_JIT_COVERAGE"}
    run_env = {**base, "PYTHONPATH": f"{tmp_path}{os.pathsep}{ROOT}", **(env or {})}
    out = subprocess.run([sys.executable, "-c", code], env=run_env, text=True,
                         capture_output=True, check=True).stdout
    return out.split()


def test_numba_skips_coverage_but_other_imports_get_it(tmp_path):
    stand_in = str(tmp_path / "coverage" / "__init__.py")
    # numba alone imports whatever module is called coverage
    assert _numba_and_coverage(tmp_path, skip=False) == ["not", "asked", "True", "True", stand_in]
    # the CLI's finder refuses it to numba's hook only
    assert _numba_and_coverage(tmp_path, skip=True) == ["True", "False", "False", stand_in]
    # NUMBA_JIT_COVERAGE asks numba for its coverage report: left as numba has it
    assert _numba_and_coverage(tmp_path, skip=True, env={"NUMBA_JIT_COVERAGE": "1"}) == [
        "False", "True", "True", stand_in]


def test_only_the_bake_command_starts_the_display_ahead():
    assert bakes(["mesh.obj", "--impact", "0,0,0"])
    assert bakes(["mesh.obj", "--cracks", "cracks.json"])
    for argv in ([], ["--help"], ["mesh.obj", "-h"], ["--version"], ["inspect", "a.exr"],
                 ["batch", "jobs.json"]):
        assert not bakes(argv), argv


def test_a_bake_collects_garbage_rarely_other_commands_as_python_does():
    import gc

    from crackbake.entry import GC_THRESHOLDS

    def thresholds(argv):
        return _run(f"import sys, gc; sys.argv = {argv!r}\n"
                    "import crackbake.cli as cli\n"
                    "cli.main = lambda **k: print(gc.get_threshold())\n"
                    "from crackbake.entry import main; main()").stdout.strip()

    assert thresholds(["crackbake", "mesh.obj", "--res", "512"]) == str(GC_THRESHOLDS)
    assert thresholds(["crackbake", "inspect", "a.exr"]) == str(gc.get_threshold())


def test_numba_skips_coverage_is_not_set_under_a_running_coverage(monkeypatch):
    monkeypatch.setitem(sys.modules, "coverage", sys)  # a coverage already imported
    before = list(sys.meta_path)
    assert numba_skips_coverage({}) is False
    assert sys.meta_path == before


def _starts(args: list[str], env: dict | None = None) -> tuple[subprocess.CompletedProcess, int]:
    """``python -m crackbake ARGS`` and how many interpreters it started (``-X importtime``
    lists ``encodings`` once per interpreter start)."""
    base = {k: v for k, v in os.environ.items() if k != "GLIBC_TUNABLES"}
    env = {**base, "PYTHONPATH": str(ROOT), **(env or {})}
    r = subprocess.run([sys.executable, "-X", "importtime", "-m", "crackbake", *args],
                       capture_output=True, text=True, env=env, timeout=120)
    return r, r.stderr.count("| encodings\n")


@pytest.mark.skipif(not os.confstr("CS_GNU_LIBC_VERSION").startswith("glibc"),
                    reason="the huge-page tunable is glibc's")
@pytest.mark.skipif(__import__("crackbake.entry").entry.gpu_present(),
                    reason="a machine with a GPU never restarts (test_a_gpu_machine_...)")
def test_a_large_bake_restarts_once_on_huge_pages_and_keeps_its_status_and_output(tmp_path):
    """A bake of --res 2048 or more restarts itself once with glibc's huge-page tunable (the
    exit frees the GL driver's render targets in 2 MiB pages); its one-line error and exit
    status are the same as without.  A smaller bake, a named command, help, the version, a
    caller's own tunable and an importing program never restart."""
    missing = str(tmp_path / "missing.obj")
    for args in ([missing], [missing, "--res", "4096"], [missing, "--res=2048"]):
        r, starts = _starts(args)
        assert starts == 2 and r.returncode == 2, (args, r.stderr[-500:])
        assert "missing.obj" in r.stderr and "Traceback" not in r.stderr
    r, starts = _starts([missing], {"GLIBC_TUNABLES": "glibc.malloc.hugetlb=0"})
    assert starts == 1 and r.returncode == 2 and "missing.obj" in r.stderr
    for args in ([missing, "--res", "1024"], ["inspect", str(tmp_path / "missing.exr")]):
        r, starts = _starts(args)
        assert starts == 1 and r.returncode == 2, (args, r.stderr[-500:])
    for args in (["--help"], ["--version"]):
        r, starts = _starts(args)
        assert starts == 1 and r.returncode == 0 and "crackbake" in r.stdout
    r = _run(f"import sys; sys.argv = ['crackbake', {missing!r}]\n"
             "import os; os.environ.pop('GLIBC_TUNABLES', None)\n"
             "print('once', flush=True)\n"
             "from crackbake.entry import main; main()")
    assert r.returncode == 2 and r.stdout.count("once") == 1, r.stdout


def test_the_restart_knows_the_groups_commands_and_the_default_res():
    from crackbake.cli.group import COMMANDS
    from crackbake.entry import HUGE_PAGES_RES, SUBCOMMANDS, _res
    from crackbake.params import RES_DEFAULT

    assert set(SUBCOMMANDS) == set(COMMANDS)
    assert _res(["mesh.obj"]) == RES_DEFAULT >= HUGE_PAGES_RES
    assert _res(["m.obj", "--res", "512", "--res=4096"]) == 4096
    assert _res(["m.obj", "--res", "big"]) == 0


def test_a_gpu_machine_does_not_restart(tmp_path):
    """A GPU's device node (NVIDIA's or a DRM render node) means the driver keeps its targets
    in the GPU's memory: no huge-page restart there; llvmpipe's machines have neither."""
    from crackbake.entry import gpu_present

    assert not gpu_present(str(tmp_path))
    (tmp_path / "dri").mkdir()
    (tmp_path / "dri" / "card0").touch()  # a display node alone: no render node
    assert not gpu_present(str(tmp_path))
    (tmp_path / "dri" / "renderD128").touch()
    assert gpu_present(str(tmp_path))
    (tmp_path / "dri" / "renderD128").unlink()
    (tmp_path / "nvidia0").touch()
    assert gpu_present(str(tmp_path))
