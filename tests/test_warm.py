"""crackbake.simulate.warm: the I&O solver's kernels loaded on a thread before the solve,
without a warning or a change to the run."""

import warnings

import numpy as np

from crackbake.simulate import warm
from crackbake.simulate.solver import SolverParams
from crackbake.simulate.solver.iben import solve_iben


def test_plate_is_a_valid_sim_mesh_and_field():
    sim, field = warm.plate(4)
    assert sim.vertices.dtype == np.float64 and sim.vertices.shape == (25, 3)
    assert sim.faces.dtype == np.int64 and sim.faces.shape == (32, 3)
    # Counter-clockwise seen from +z, every face with area.
    p = sim.vertices[sim.faces]
    cross = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    assert (cross[:, 2] > 0).all()
    # In-plane, symmetric, tension: the loop has something to crack.
    assert np.allclose(field.stress, np.swapaxes(field.stress, 1, 2))
    assert np.allclose(field.stress[:, 2], 0.0)
    assert np.trace(field.stress, axis1=1, axis2=2).max() > 0


def test_warm_loads_the_loop_kernels_without_warnings():
    from crackbake.simulate.solver.iben import loop, update

    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a warning from the thread would land in a run's list
        warm.warm()
    for kernel in (loop.run, update.rebuild, update.incidence, update.update_faces,
                   update.update_nodes):
        assert kernel.signatures, kernel  # compiled or loaded for the types a run uses
    # The plate cracks (the loop ran its events), and the same way twice.
    sim, field = warm.plate()
    a = solve_iben(sim, field, SolverParams(max_steps=50, max_cracks=4))
    b = solve_iben(sim, field, SolverParams(max_steps=50, max_cracks=4))
    assert a.steps > 0
    assert len(a.cracks) == len(b.cracks) > 0
    for ca, cb in zip(a.cracks, b.cracks, strict=True):
        np.testing.assert_array_equal(ca.points, cb.points)


def test_start_runs_a_daemon_thread_that_ends():
    thread = warm.start()
    assert thread.daemon
    thread.join(120)
    assert not thread.is_alive()


def test_the_long_kernels_release_the_gil():
    # The solve is seconds of one kernel on the run's thread; holding the GIL it kept the
    # warm-up's loads, the targets' allocation and the gutter plan off the idle core.
    from crackbake.bake import dilation, grid
    from crackbake.simulate import timing
    from crackbake.simulate.solver.iben import loop, update
    from crackbake.simulate.solver.thesis import growth

    for kernel in (loop.run, update.rebuild, update.requeue_all, growth.grow, timing._arrival,
                   grid._bin_candidates, dilation._fill_plan):
        assert kernel.targetoptions.get("nogil") is True, kernel.py_func.__qualname__


def test_named_modules_are_imported_on_the_thread_and_a_bad_name_is_ignored():
    # The pipeline hands the writer's modules by name: imported beside the solve, not after it.
    import subprocess
    import sys

    code = (
        "import sys\n"
        "from crackbake.simulate import warm\n"
        "assert 'crackbake.exchange.manifest' not in sys.modules\n"
        "t = warm.start(['crackbake.no_such_module', 'crackbake.exchange.manifest'])\n"
        "t.join(120)\n"
        "print('crackbake.exchange.manifest' in sys.modules, t.is_alive())\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=180, check=True)  # fmt: skip
    assert out.stdout.split() == ["True", "False"], out.stderr


def test_named_kernels_load_on_the_thread_and_a_bad_name_is_ignored():
    # "module:kernel": the module imports there and the kernel loads from the cache there
    # (crackbake.exchange.halving is not imported by the solver; its kernel is loaded once the
    # thread is done, without a call), a missing module or kernel is skipped.
    import subprocess
    import sys

    # in the cache first (the suite's precompiled cache has it; a bare checkout may not)
    subprocess.run([sys.executable, "-c", "import numpy as np; from crackbake.exchange.halving "
                    "import mip_half; mip_half(np.zeros((4, 4, 3), np.uint8))"],
                   capture_output=True, timeout=180, check=True)  # fmt: skip
    code = (
        "import sys\n"
        "from crackbake.simulate import warm\n"
        "assert 'crackbake.exchange.halving' not in sys.modules\n"
        "t = warm.start(['crackbake.no_such_module:kernel', 'crackbake.nearest:no_such_kernel',\n"
        "                'crackbake.exchange.halving:_mip_half'])\n"
        "t.join(120)\n"
        "from crackbake.exchange import halving\n"
        "print('loaded' if halving._mip_half.signatures else 'not loaded', t.is_alive())\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=180, check=True)  # fmt: skip
    assert out.stdout.split() == ["loaded", "False"], out.stderr


def test_after_holds_the_loads_until_it_is_set():
    # The pipeline starts the thread before the field's kernels load on the run's thread: the
    # thread imports the solver, then loads nothing until it is told.
    import subprocess
    import sys

    code = (
        "import sys, threading, time\n"
        "from crackbake.simulate import warm\n"
        "from crackbake.simulate.solver.iben import update\n"
        "after = threading.Event()\n"
        "t = warm.start((), None, after)\n"
        "time.sleep(1.0)\n"
        "held = (not update.update_nodes.signatures, t.is_alive())\n"
        "after.set()\n"
        "t.join(120)\n"
        "print(*held, bool(update.update_nodes.signatures), t.is_alive())\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=180, check=True)  # fmt: skip
    assert out.stdout.split() == ["True", "True", "True", "False"], out.stderr


def test_without_the_plate_only_the_named_kernels_load():
    # A re-bake's thread: no solver to warm, only the later stages' kernels.
    import subprocess
    import sys

    code = (
        "import sys\n"
        "from crackbake.simulate import warm\n"
        "t = warm.start(['crackbake.exchange.halving:_mip_half'], plate=False)\n"
        "name = t.name\n"
        "t.join(120)\n"
        "from crackbake.exchange import halving\n"
        "print(name, 'crackbake.simulate.solver.iben.solve' in sys.modules,\n"
        "      bool(halving._mip_half.signatures))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=180, check=True)  # fmt: skip
    assert out.stdout.split() == ["crackbake-kernels", "False", "True"], out.stderr
