# The two set-up commands of the README.  Both are idempotent and quick when already done.
PY       ?= python3
VENV     := .venv
VPY      := $(VENV)/bin/python
STAMP    := $(VENV)/.installed
TSTAMP   := $(VENV)/.installed-test
KSTAMP   := $(VENV)/.precompiled
APT_PKGS := libegl1 libegl-mesa0 libgl1 libgl1-mesa-dri libgbm1

# The reference readers `make test` checks the outputs with (docs/development.md): Blender as a
# module (its bpy wheel is built for Python 3.11 only and pins numpy<2, so it gets an environment
# of its own) and the Khronos glTF validator from npm.  Both are cached in ignored folders.
PY311    ?= python3.11
BPY_VENV := .venv-blender
BPY      := $(BPY_VENV)/bin/python
BPY_PIN  := bpy==5.0.1
# the stamps name the pinned versions, so changing a pin re-installs
BPY_STAMP := $(BPY_VENV)/.installed-$(subst ==,-,$(BPY_PIN))
NODE_DIR := .node
GLTFV_PIN := gltf-validator@2.0.0-dev.3.10
GLTFV    := $(NODE_DIR)/.installed-$(subst @,-,$(GLTFV_PIN))

# `make test` compiles the kernels afresh into a numba cache of its own (NUMBA_CACHE_DIR), and
# that one compile serves twice: every test process loads its kernels from it, and a copy taken
# before any test runs, exactly what `crackbake.precompile` wrote into an empty cache, is what
# tests/test_precompile.py checks a first run against (run alone, that test compiles its own).
TEST_KERNELS := $(VENV)/numba-test
PRECOMPILED  := $(VENV)/numba-precompiled

.PHONY: demo test test-kernels check setup syslibs references lint bench clean

setup: syslibs $(STAMP) $(TSTAMP) $(KSTAMP)

# The package and what a run needs first; the test tools (ray, usd-core, pytest...) after it, in
# a step of their own, so that `make test` installs them while the kernels compile.  Every
# module is byte-compiled once, on all cores (compileall -j 0; pip's own compile is one core):
# where PYTHONDONTWRITEBYTECODE is set (many containers and CI images) Python never writes a
# .pyc, and each process would compile numpy, scipy, trimesh and numba from source again (3.0
# instead of 1.6 CPU s to import them; ray's workers likewise).  A file that does not compile
# (some packages ship templates) is no reason to stop, hence the leading '-'.
$(STAMP): pyproject.toml
	@$(VPY) -m pip --version >/dev/null 2>&1 || { rm -rf $(VENV) && $(PY) -m venv $(VENV); }
	$(VPY) -m pip install --quiet --upgrade pip
	$(VPY) -m pip install --quiet --no-compile -e .
	-$(VPY) -m compileall -qq -j 0 $(VENV)/lib crackbake
	@touch $(STAMP)

# (the extra's requirements alone: `-e '.[test]'` would reinstall the package under the compile)
$(TSTAMP): $(STAMP)
	$(VPY) -c "import tomllib; print('\\n'.join(tomllib.load(open('pyproject.toml', 'rb'))['project']['optional-dependencies']['test']))" > $(VENV)/test-requirements.txt
	$(VPY) -m pip install --quiet --no-compile -r $(VENV)/test-requirements.txt
	-$(VPY) -m compileall -qq -j 0 $(VENV)/lib
	@touch $(TSTAMP)

# numba compiles its kernels once into the on-disk cache here, not in the first run.
$(KSTAMP): $(STAMP)
	$(VPY) -m crackbake.precompile
	@touch $(KSTAMP)

test-kernels: syslibs $(STAMP)
	rm -rf $(TEST_KERNELS) $(PRECOMPILED)
	NUMBA_CACHE_DIR=$(abspath $(TEST_KERNELS)) $(VPY) -m crackbake.precompile
	cp -a $(TEST_KERNELS) $(PRECOMPILED)

# glcontext dlopens libGL and libEGL; without libgl1-mesa-dri EGL fails with 0x3001.
syslibs:
	@missing=""; for p in $(APT_PKGS); do \
	  dpkg-query -W -f='$${Status}' $$p 2>/dev/null | grep -q "ok installed" || missing="$$missing $$p"; \
	done; \
	if [ -n "$$missing" ]; then \
	  if ! command -v apt-get >/dev/null 2>&1; then \
	    echo "crackbake needs EGL + Mesa (packages:$$missing); install your distribution's equivalents."; exit 1; \
	  elif [ "$$(id -u)" = "0" ]; then \
	    echo "installing system libraries:$$missing"; \
	    DEBIAN_FRONTEND=noninteractive apt-get install -y -q $$missing >/dev/null || \
	      { apt-get update -q >/dev/null && DEBIAN_FRONTEND=noninteractive apt-get install -y -q $$missing >/dev/null; }; \
	  else \
	    echo "missing system libraries:$$missing"; \
	    echo "run: sudo apt-get install -y$$missing   (then make again)"; exit 1; \
	  fi; \
	fi

demo: setup
	$(VENV)/bin/crackbake examples/spot.obj --preset glass --impact 0.334,0.044,0.287 --res 2048 -o spot_cracks
	@echo
	@echo "Outputs are in ./spot_cracks/ (docs/outputs.md):"
	@echo "  spot_cracks.exr  EXR master: crack.<map>.V layers + crack.normal (linear, mesh units)"
	@echo "  spot_stress.exr  initial and final stress in the tangent frame (crackbake inspect it)"
	@echo "  spot_basecolor/normal/orm/data.png  glTF texture set; spot_mask.png, spot_depth.png"
	@echo "  spot.glb         the mesh with base colour, normal and occlusion maps (any glTF viewer)"
	@echo "  preview.png      the result lit with its normal map"
	@echo "  cracks.json      crack network sidecar (re-bake it with --cracks)  cracks.obj  polylines"
	@echo "  manifest.json    inputs, parameters, files, timings"

references: $(BPY_STAMP) $(GLTFV)

$(BPY_STAMP):
	@command -v $(PY311) >/dev/null 2>&1 || { echo "make test needs $(PY311) for Blender's bpy wheel (built for Python 3.11 only); install it or pass PY311=/path/to/python3.11"; exit 1; }
	@# an environment left half-made (an interrupted venv has no pip) is made again
	@$(BPY) -m pip --version >/dev/null 2>&1 || { rm -rf $(BPY_VENV) && $(PY311) -m venv $(BPY_VENV); }
	$(BPY) -m pip install --quiet --upgrade pip
	$(BPY) -m pip install --quiet --no-compile $(BPY_PIN)
	-$(BPY) -m compileall -qq -j 0 $(BPY_VENV)/lib
	$(BPY) -c "import bpy"
	@touch $(BPY_STAMP)

$(GLTFV):
	@command -v npm >/dev/null 2>&1 || { echo "make test needs Node.js and npm for the Khronos glTF validator (apt-get install -y nodejs npm)"; exit 1; }
	npm install --prefix $(NODE_DIR) --no-audit --no-fund --loglevel=error $(GLTFV_PIN)
	@touch $(GLTFV)

# Every test, the reference checks included: CRACKBAKE_REFERENCE=require turns a skipped
# reference check (Blender, glTF validator: pytest marker `reference`) into a failure.
# The set-ups overlap: the test tools' install and the reference downloads (bpy is a 300 MB
# wheel) wait on the network and the disk while the kernel precompile keeps the cores busy.
test:
	@$(MAKE) --no-print-directory -j3 test-kernels $(TSTAMP) references
	$(VPY) -m ruff check crackbake tests benchmarks examples
	NUMBA_CACHE_DIR=$(abspath $(TEST_KERNELS)) CRACKBAKE_PRECOMPILED_CACHE=$(abspath $(PRECOMPILED)) \
	  CRACKBAKE_BLENDER_PYTHON=$(abspath $(BPY)) CRACKBAKE_GLTF_VALIDATOR=$(abspath $(NODE_DIR)) \
	  CRACKBAKE_REFERENCE=require $(VPY) -m pytest -q -n auto --dist loadfile --durations=30

# The quick loop while editing: ruff and every test not marked slow or reference.
check: setup
	$(VPY) -m ruff check crackbake tests benchmarks examples
	$(VPY) -m pytest -q -m "not slow and not reference"

bench: setup
	$(VPY) benchmarks/bench_bake.py
	$(VPY) benchmarks/bench_solver.py
	$(VPY) benchmarks/bench_pipeline.py
	$(VPY) benchmarks/bench_scale.py
	$(VPY) benchmarks/bench_compile.py
	$(VPY) benchmarks/bench_resolution.py

# numba's kernel cache (*.nbi, *.nbc) lives in the __pycache__ folders beside the sources.
clean:
	rm -rf $(VENV) $(BPY_VENV) $(NODE_DIR) build dist *.egg-info spot_cracks .pytest_cache
	find crackbake tests benchmarks examples -name __pycache__ -type d -prune -exec rm -rf {} +
	rm -rf $${TMPDIR:-/tmp}/crackbake-numba-$$(id -u)
