# dolfinx_dem: setup / test / demo / bench.
#
# DOLFINx and friends come from Debian packages run by /usr/bin/python3 (Debian 12:
# DOLFINx 0.5.2; Debian 13: 0.9.0); the package itself and the few PyPI-only
# dependencies (pyvista, imageio, ruff) go into .venv, created with
# --system-site-packages so the Debian modules are visible. Every pip install is
# constrained to the system's numpy (.venv/constraints.txt, written from it): a
# newer numpy breaks the compiled DOLFINx.
#
# `make setup` is idempotent and takes a few seconds once everything is done:
# apt-get only runs if dpkg reports a package missing, and pip only runs when
# pyproject.toml or the C kernels (dolfinx_dem/kernels/, built by cffi at install) are
# newer than .venv/.installed.

SHELL := /bin/bash
.DEFAULT_GOAL := setup

SYSTEM_PYTHON := /usr/bin/python3
VENV          := .venv
PYTHON        := $(VENV)/bin/python
STAMP         := $(VENV)/.installed
MPI_NP        ?= 2 3
PYTEST_ARGS   ?=

# Debian packages. openmpi-bin provides mpirun; the GL/EGL libraries let the
# VTK wheel used by pyvista render off-screen (EGL, no X server needed).
APT_PACKAGES := \
	python3-dolfinx-real python3-gmsh python3-matplotlib python3-pytest \
	python3-venv python3-dev python3-scipy python3-slepc4py python3-cffi \
	python3-setuptools python3-wheel openmpi-bin ca-certificates gcc \
	libgl1 libegl1 libegl-mesa0 libgl1-mesa-dri

PIP_PACKAGES := pyvista imageio ruff==0.17.6

export OMPI_ALLOW_RUN_AS_ROOT=1
export OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
# Containers often forbid the cross-memory-attach (ptrace) used by Open MPI's
# shared-memory transport; copying through shared memory works everywhere.
export OMPI_MCA_btl_vader_single_copy_mechanism=none
export OMPI_MCA_btl_sm_single_copy_mechanism=none  # the same transport's name in Open MPI 5 (Debian 13)
export PYVISTA_OFF_SCREEN=true

.PHONY: setup apt verify lint test test-fast trixie-tree test-trixie demo bench validate clean

setup: $(STAMP) verify

# --- Debian packages (only when some are missing) ----------------------------
apt:
	@command -v dpkg-query >/dev/null 2>&1 || { \
	  echo "error: dpkg-query not found; this project needs Debian 12 (bookworm)." >&2; exit 1; }
	@missing=""; \
	for p in $(APT_PACKAGES); do \
	  dpkg-query -W -f='$${db:Status-Abbrev}' "$$p" 2>/dev/null | grep -q '^ii' || missing="$$missing $$p"; \
	done; \
	if [ -n "$$missing" ]; then \
	  if [ "$$(id -u)" -eq 0 ]; then SUDO=""; \
	  elif command -v sudo >/dev/null 2>&1; then SUDO="sudo"; \
	  else \
	    echo "error: missing Debian packages:$$missing" >&2; \
	    echo "error: not root and sudo is not available; as root run:" >&2; \
	    echo "  apt-get update && apt-get install -y --no-install-recommends$$missing" >&2; \
	    exit 1; \
	  fi; \
	  echo "Installing missing Debian packages:$$missing"; \
	  if [ -z "$${APT_UPDATED:-}" ]; then $$SUDO apt-get update; fi; \
	  $$SUDO env DEBIAN_FRONTEND=noninteractive \
	    apt-get install -y --no-install-recommends $$missing; \
	fi

# --- virtual environment ------------------------------------------------------
$(PYTHON): | apt
	$(SYSTEM_PYTHON) -m venv --system-site-packages $(VENV)

$(VENV)/constraints.txt: | $(PYTHON)
	$(SYSTEM_PYTHON) -c "import numpy; print('numpy==' + numpy.__version__)" > $@

$(STAMP): pyproject.toml setup.py $(wildcard dolfinx_dem/kernels/*.c dolfinx_dem/kernels/*.h) dolfinx_dem/kernels/_build.py | $(VENV)/constraints.txt
	$(PYTHON) -m pip install --disable-pip-version-check -q \
	  -c $(VENV)/constraints.txt --no-build-isolation -e . $(PIP_PACKAGES)
	@touch $@

verify: | $(STAMP)
	@$(PYTHON) -c "import dolfinx, numpy; assert numpy.__file__.startswith('/usr/lib/python3/')" || { \
	  echo "error: $(VENV) does not import DOLFINx with the system's numpy." >&2; \
	  echo "error: recreate it with: rm -rf $(VENV) && make setup" >&2; exit 1; }

# --- tests --------------------------------------------------------------------
# `make test`: the linter, then the whole suite serially, then the tests marked `mpi` under
# mpirun on each process count of MPI_NP (2 and 3: an odd count finds what 2 hides).
# `make test-fast`: the same without the end-to-end tests marked `slow` (scene runs, demos,
# studies), under 2 minutes. pytest exit code 5 (nothing collected) is only tolerated when
# there are no mpi-marked tests at all; any other failure is propagated.
lint: setup
	$(PYTHON) -m ruff check .

test: export OMP_NUM_THREADS = 1
test: lint
	$(MAKE) --no-print-directory pytest MARKS=

test-fast: export OMP_NUM_THREADS = 1
test-fast: lint
	$(MAKE) --no-print-directory pytest MARKS="not slow" MPI_NP=2

MARKS ?=
AND_MARKS = $(if $(MARKS), and ($(MARKS)),)
.PHONY: pytest
pytest: export OMP_NUM_THREADS = 1
pytest:
	$(PYTHON) -m pytest -q $(if $(MARKS),-m "$(MARKS)") $(PYTEST_ARGS) tests
	@$(PYTHON) -m pytest -q -m "mpi$(AND_MARKS)" --collect-only -p no:cacheprovider tests >/dev/null 2>&1; rc=$$?; \
	if [ $$rc -eq 5 ]; then echo "No tests marked 'mpi': skipping the mpirun run."; exit 0; \
	elif [ $$rc -ne 0 ]; then echo "error: collecting mpi tests failed (exit $$rc)" >&2; exit $$rc; fi; \
	for np in $(MPI_NP); do \
	  echo "mpirun -n $$np --oversubscribe $(PYTHON) -m pytest -q -m 'mpi$(AND_MARKS)' -p no:cacheprovider $(PYTEST_ARGS) tests"; \
	  mpirun -n $$np --oversubscribe $(PYTHON) -m pytest -q -m "mpi$(AND_MARKS)" -p no:cacheprovider $(PYTEST_ARGS) tests || exit $$?; \
	done

# --- Debian 13 (DOLFINx 0.9), the second tested platform ------------------------
# `make test-trixie` runs `make test` in a Debian 13 tree (a chroot made by debootstrap
# once, cached in TRIXIE outside the repository) on a copy of this checkout. As root.
TRIXIE ?= /var/cache/dolfinx-dem/trixie
trixie-tree:
	bash .ci/trixie.sh tree $(TRIXIE) "$(APT_PACKAGES) make git"

test-trixie: trixie-tree
	bash .ci/trixie.sh test $(TRIXIE)

# --- demo / benchmarks / validation ----------------------------------------------
demo: setup
	$(VENV)/bin/dolfinx-dem run cantilever --out results/cantilever --overwrite
	@echo "Results of the cantilever scene are in $(CURDIR)/results/cantilever"

# The benchmark studies of docs/bench/README.md (~50 min; ~17 GB for the largest parallel run).
bench: export OMP_NUM_THREADS = 1
bench: setup
	$(PYTHON) benchmarks/bench_study.py
	$(PYTHON) benchmarks/bench_signorini.py
	$(PYTHON) benchmarks/bench_wave2d.py
	$(PYTHON) benchmarks/bench_contact_scaling.py --out docs/bench/contact_scaling.json
	$(PYTHON) benchmarks/bench_contact3d.py --out docs/bench/contact3d.json
	$(PYTHON) benchmarks/bench_femp1.py --out docs/bench/femp1.json
	$(PYTHON) benchmarks/bench_parallel.py --out docs/bench/parallel.json

# The validation studies of docs/validation/README.md (about 4.9 h by their JSON's wall times):
# each writes its JSON and page there. The pages written by the demos and the 3D contact runs give
# their own commands. hertz3d_diagnostics adds its levels to its JSON, so that starts empty.
VALIDATE_WORK := results/validate
validate: export OMP_NUM_THREADS = 1
validate: setup
	$(PYTHON) validation/bar_traction.py --out docs/validation/bar_traction.json
	$(PYTHON) validation/two_materials.py --meshes 350 700 1400 2800 --out docs/validation/two_materials.json
	$(PYTHON) validation/scheme_b.py --out docs/validation/scheme_b.json
	$(PYTHON) validation/long_bounce.py --n 100 200 400 --out docs/validation/long_bounce.json
	$(PYTHON) validation/long_runs.py --out docs/validation/long_runs.json
	rm -f docs/validation/cradle_drift.json
	for s in 1 0.1; do \
	  for h in 0.042 0.04 0.038 0.028; do \
	    $(PYTHON) validation/cradle_drift.py --out docs/validation/cradle_drift.json --method dem-B --h $$h --speed $$s && \
	    $(PYTHON) validation/cradle_drift.py --out docs/validation/cradle_drift.json --method fem-P1 --h $$h --speed $$s && \
	    $(PYTHON) validation/cradle_drift.py --out docs/validation/cradle_drift.json --method dem-B --h $$h --speed $$s --set contact.surface=vertex || exit 1; \
	  done; \
	  $(PYTHON) validation/cradle_drift.py --out docs/validation/cradle_drift.json --method dem-B --h 0.04 --speed $$s --set material.eta=1000 && \
	  $(PYTHON) validation/cradle_drift.py --out docs/validation/cradle_drift.json --method dem-B --h 0.04 --speed $$s --set time.cfl=0.1 && \
	  $(PYTHON) validation/cradle_drift.py --out docs/validation/cradle_drift.json --method fem-P1 --h 0.04 --speed $$s --set time.cfl=0.1 || exit 1; \
	done
	$(PYTHON) validation/cradle_drift.py --page docs/validation/cradle_drift.md --out docs/validation/cradle_drift.json
	$(PYTHON) validation/friction_slide.py --out docs/validation/friction.json
	$(PYTHON) validation/friction_slide.py --scheme B --out docs/validation/friction_scheme_b.json
	$(PYTHON) validation/friction_slide.py --scheme AB --out docs/validation/friction_scheme_ab.json
	$(PYTHON) validation/oblique_impact.py --out docs/validation/oblique_impact.json
	$(PYTHON) validation/friction_bodies.py --out docs/validation/friction_bodies.json
	$(PYTHON) validation/friction_chatter.py --out docs/validation/friction_chatter.json
	$(PYTHON) validation/cattaneo_mindlin.py --out docs/validation/cattaneo_mindlin.json
	$(PYTHON) validation/cattaneo_mindlin_bodies.py --out docs/validation/cattaneo_mindlin_bodies.json
	$(PYTHON) validation/hertz_impact.py --levels 0.006 0.004 0.0027 --methods dem-B dem-A --etas 100 1000 --h 0.03 --radius 0.03 --speed 0.02 --cfl 0.5 --out docs/validation/hertz_impact.json
	$(PYTHON) validation/hertz_impact.py --levels 0.006 --methods dem-A --etas 100 --h 0.03 --radius 0.06 --speed 0.02 --cfl 0.5 --append --out docs/validation/hertz_impact.json
	$(PYTHON) validation/hertz_impact.py --levels 0.006 --methods dem-A --etas 100 --h 0.015 --radius 0.03 --speed 0.02 --cfl 0.5 --append --out docs/validation/hertz_impact.json
	$(PYTHON) validation/hertz_impact.py --levels 0.006 0.004 --methods fem-P1 --h 0.03 --radius 0.03 --speed 0.02 --cfl 0.5 --append --out docs/validation/hertz_impact.json
	$(PYTHON) validation/hertz_impact.py --levels 0.0027 --methods fem-P1 --h 0.03 --radius 0.03 --speed 0.02 --cfl 0.5 --append --out docs/validation/hertz_impact.json
	$(PYTHON) validation/hertz_impact.py --levels 0.006 --methods fem-P1 --h 0.015 --radius 0.03 --speed 0.02 --cfl 0.5 --append --out docs/validation/hertz_impact.json
	$(PYTHON) validation/hertz_impact.py --levels 0.006 0.004 --methods dem-B dem-A --etas 100 --surfaces vertex --h 0.03 --radius 0.03 --speed 0.02 --cfl 0.5 --append --out docs/validation/hertz_impact.json
	$(PYTHON) validation/hertz_impact.py --levels 0.006 0.004 --methods dem-A --etas 100 --h 0.015 --radius 0.03 --speed 0.01 --cfl 0.5 --out docs/validation/hertz_impact_slow.json
	$(PYTHON) validation/hertz_impact.py --levels 0.006 --methods fem-P1 --h 0.015 --radius 0.03 --speed 0.01 --cfl 0.5 --append --out docs/validation/hertz_impact_slow.json
	$(PYTHON) validation/kill_loop.py --processes 1 2 3 --kills 140 30 30 --out docs/validation/kill_loop.json
	$(PYTHON) validation/indentation_fem.py --out docs/validation/indentation_fem.json
	$(PYTHON) validation/indentation_fem.py --meshes 0.0005 --out docs/validation/indentation_fem_fine.json
	mkdir -p $(VALIDATE_WORK)
	$(PYTHON) validation/indentation.py --h 0.04 0.02 --speeds 0.5 0.25 --slow-h 0.04 --slow-speeds 0.125 --static-h --out $(VALIDATE_WORK)/a.json
	$(PYTHON) validation/indentation.py --h 0.01 --speeds 0.5 --slow-h --static-h --out $(VALIDATE_WORK)/b.json
	$(PYTHON) validation/indentation.py --h --static-h 0.04 0.02 0.01 --out $(VALIDATE_WORK)/c.json
	$(PYTHON) validation/indentation.py --h 0.02 --speeds 0.0625 --slow-h --static-h --out $(VALIDATE_WORK)/d.json
	$(PYTHON) validation/indentation.py --merge $(VALIDATE_WORK)/{a,b,c,d}.json --out docs/validation/indentation.json
	$(PYTHON) validation/hertz3d.py --scales 1 1.41 2 2.83 --fem-extra 4 --work $(VALIDATE_WORK)/hertz3d
	rm -f docs/validation/hertz3d_diagnostics.json
	$(PYTHON) validation/hertz3d_diagnostics.py --dem --fem --scales 0.5 0.71 1 1.41 2
	$(PYTHON) validation/hertz3d_diagnostics.py --dem --scales 2.83
	$(PYTHON) validation/hertz3d_diagnostics.py --dem --fem --scales 0.9 1.1 1.3 1.55 1.8 2.2
	$(PYTHON) validation/hertz3d_diagnostics.py --fem --scales 2 --load-factors 0.9 1.1
	$(PYTHON) validation/hertz3d_diagnostics.py --dem --fem --scales 2.5 3.0

# --- cleaning (keeps .venv) -----------------------------------------------------
clean:
	rm -rf results build dist *.egg-info .pytest_cache
	find . -path ./$(VENV) -prune -o -name __pycache__ -type d -print0 | xargs -0 rm -rf
