# softjoint — FEM bellow joint -> torch surrogate -> gripper gesture predictor.
# `make` prints this help. `make demo` and `make test` each do their own set-up.

SHELL := /bin/bash
VENV  := .venv
PY    := $(VENV)/bin/python
SETUP := $(VENV)/.setup-done
MPIRUN := mpirun --oversubscribe
# OpenMPI refuses root without these; we are root on the workstations and in CI.
export OMPI_ALLOW_RUN_AS_ROOT := 1
export OMPI_ALLOW_RUN_AS_ROOT_CONFIRM := 1
# One BLAS/OpenMP thread per MPI rank: ranks, not threads, use the cores.
export OMP_NUM_THREADS := 1
export OPENBLAS_NUM_THREADS := 1
export PYVISTA_OFF_SCREEN := true
APT_PACKAGES := python3-dolfinx python3-gmsh python3-meshio python3-scipy python3-venv openmpi-bin

.DEFAULT_GOAL := help
.PHONY: help setup demo test test-fast bench bench-fem mesh-study joint-render self-contact \
        dataset dataset-smoke bench-campaign train gestures bench-predictor report clean

help: ## show this help
	@echo "softjoint make targets (README.md explains each):"
	@grep -hE '^[a-zA-Z_./%-]+:.*## ' $(MAKEFILE_LIST) | \
	  awk 'BEGIN {FS = ":.*## "}; {printf "  \033[36m%-34s\033[0m %s\n", $$1, $$2}'

# ---------------------------------------------------------------- set-up
setup: $(SETUP) ## install Debian FEniCSx (apt) and the .venv (idempotent)

$(SETUP): pyproject.toml constraints.txt
	@if ! /usr/bin/python3 -c "import dolfinx, gmsh, scipy" 2>/dev/null || ! command -v mpirun >/dev/null; then \
	  echo "[setup] apt-get install $(APT_PACKAGES)"; \
	  apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends $(APT_PACKAGES); \
	fi
	@test -x $(PY) || /usr/bin/python3 -m venv --system-site-packages $(VENV)
	$(VENV)/bin/pip install -q -c constraints.txt torch==2.13.0 pyvista pytest matplotlib
	$(VENV)/bin/pip install -q -c constraints.txt --no-deps --no-build-isolation -e .
	@$(PY) -c "import dolfinx, torch, pyvista, numpy; print('[setup] dolfinx', dolfinx.__version__, '| torch', torch.__version__, '| numpy', numpy.__version__)"
	@touch $@

# ---------------------------------------------------------------- main commands
demo: $(SETUP) ## the main job on the committed defaults (FEM case, surrogate, gesture)
	$(PY) -m workflow.demo

test: $(SETUP) ## the test suite (coarse FEM, small data; < 15 min)
	$(PY) -m pytest -q -ra

# ---------------------------------------------------------------- fem (issue 2)
bench-fem: results/bench/fem.json ## FEM timings at the production mesh -> results/bench/fem.json
results/bench/fem.json: fem/*.py | $(SETUP)
	$(PY) -m fem.bench --out $@

mesh-study: results/fem/mesh_study.json ## 4 corner cases x 3 meshes -> results/fem/mesh_study.json
results/fem/mesh_study.json: fem/*.py | $(SETUP)
	$(PY) -m fem.mesh_study --out $@

self-contact: results/fem/self_contact.json ## min wall gap over the box corners
results/fem/self_contact.json: fem/*.py | $(SETUP)
	$(PY) -m fem.self_contact --out $@

joint-render: results/fem/joint.png ## pyvista render of the joint, undeformed + deformed
results/fem/joint.png: fem/*.py | $(SETUP)
	$(PY) -m fem.render --out $@

# ---------------------------------------------------------------- campaign (issue 3)
# (section owned by workflow/)

# ---------------------------------------------------------------- surrogate (issue 4)
# (section owned by surrogate/)

# ---------------------------------------------------------------- predictor (issue 5)
# (section owned by predictor/)

clean: ## remove the venv and caches (keeps results/)
	rm -rf $(VENV) .pytest_cache build *.egg-info
