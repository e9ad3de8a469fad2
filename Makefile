# softjoint — FEM bellow joint -> torch surrogate -> gripper gesture predictor.
# `make` prints this help. `make demo` and `make test` each do their own set-up.

SHELL := /bin/bash
VENV  := .venv
PY    := $(VENV)/bin/python
SETUP := $(VENV)/.setup-done
MPIRUN := mpirun -q --oversubscribe
# OpenMPI refuses root without these; we are root on the workstations and in CI.
export OMPI_ALLOW_RUN_AS_ROOT := 1
export OMPI_ALLOW_RUN_AS_ROOT_CONFIRM := 1
# One BLAS/OpenMP thread per MPI rank: ranks, not threads, use the cores.
export OMP_NUM_THREADS := 1
export OPENBLAS_NUM_THREADS := 1
export PYVISTA_OFF_SCREEN := true
# slurm-wlm + munge: tests/test_slurm.py runs workflow/slurm/campaign.sbatch on a throw-away
# one-node cluster (the daemons are never started as services). libopenblas0-serial: without
# it (--no-install-recommends) MUMPS and numpy get the reference BLAS, 4x slower LU. g++:
# torch.compile's C++ (bench-predictor --graphs compile; dolfinx pulls in only g++-12).
APT_PACKAGES := python3-dolfinx python3-gmsh python3-meshio python3-scipy python3-venv openmpi-bin \
                slurm-wlm munge libopenblas0-serial g++

# A fresh clone's file times are the order git wrote the files in: code written after a
# committed checkpoint would look newer, and `make bench-predictor` would retrain the
# surrogate and the NNs (hours) before measuring them. The committed tree is one
# consistent state, so once per clone, while its tree is clean, every tracked file gets
# the time of the last commit; from then on an edit makes its dependants stale as usual.
# It is the first prerequisite of every artefact (never done at parse time, so `make help`
# changes nothing); the marker carries the commit's time, so it never makes a target stale,
# and its `+` runs it under `make -n` too (a dry run then plans what a real run would do).
GIT_DIR := $(shell git rev-parse --absolute-git-dir 2>/dev/null)
TIMES   := $(if $(GIT_DIR),$(GIT_DIR)/softjoint-times)

ifneq ($(TIMES),)
$(TIMES):
	+@t=$$(git log -1 --format=%ct); \
	  if test -z "$$(git status --porcelain --untracked-files=no)"; then git ls-files -z | xargs -0 touch -c -d @$$t; fi; \
	  touch -d @$$t $@
endif

# The discretisations (fem/mesh/discretisation.py). Every tool defaults to the production one,
# the paper joint file's [mesh]: swept Q2 hexahedra hex2:3 in the mixed u-p formulation
# (docs/decisions.md §9), and so do the committed datasets results/data/{train,heldout}, the
# surrogate results/surrogate/ trained on them, the predictor's results/predictor/ and the
# calibration's truth cases (issue 55 §3, the switch). The paper-fidelity PAPER, 1.8 mm P2
# tetrahedra in displacement, is the reference REPORT compares against: its walks
# results/data/{train,heldout}_h1.8 (and the 1.697:0.849 held-out walk), the surrogate and
# predictor in results/{surrogate,predictor}/h1.8/ and the lone-finger cases of
# results/validation/finger_fem/<case>.json; every target that resumes, extends, checks or
# redraws one of them passes PAPER_MESH, so that it keeps doing what it did, and
# docs/decisions.md §9 gives the variables that rebuild the rest.
PAPER_MESH := --mesh-size 1.8 --formulation displacement
PROD_MESH  := --divisions 2 --hex-size 3 --formulation mixed

.DEFAULT_GOAL := help
.PHONY: help setup demo test bench-fem bench-finger mesh-study mesh-study-tet mesh-causes materials joint-render self-contact joint-outline validation \
        dataset dataset-fine fine-compare production-compare dataset-smoke bench-campaign train sweep learning-curve bench-surrogate failed-samples resolve-samples multifidelity gestures bench-predictor atlas atlas-reference atlas-reference-fine inverse track calibrate-recovery calibration-fem calibrate-demo bench-calibrate finger-fem finger-grid grasp-fem validate-grasps validate-finger validate-finger-h1.8 report clean

help: ## show this help
	@echo "softjoint make targets (README.md explains each):"
	@grep -hE '^[a-zA-Z0-9_./%-]+:.*## ' $(MAKEFILE_LIST) | \
	  awk 'BEGIN {FS = ":.*## "}; {printf "  \033[36m%-34s\033[0m %s\n", $$1, $$2}'

# ---------------------------------------------------------------- set-up
setup: $(SETUP) ## install Debian FEniCSx (apt) and the .venv (idempotent)

$(SETUP): pyproject.toml constraints.txt
	@if ! /usr/bin/python3 -c "import dolfinx, gmsh, scipy" 2>/dev/null || ! command -v mpirun >/dev/null \
	     || ! command -v slurmctld >/dev/null || ! command -v munged >/dev/null \
	     || ! dpkg -s libopenblas0-serial >/dev/null 2>&1 || ! command -v g++ >/dev/null; then \
	  echo "[setup] apt-get install $(APT_PACKAGES)"; \
	  apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends $(APT_PACKAGES); \
	fi
	@test -x $(PY) || /usr/bin/python3 -m venv --system-site-packages $(VENV)
	$(VENV)/bin/pip install -q -c constraints.txt torch==2.13.0 pyvista pytest pytest-xdist matplotlib
	$(VENV)/bin/pip install -q -c constraints.txt --no-deps --no-build-isolation -e .
	@$(PY) -c "import dolfinx, torch, pyvista, numpy; print('[setup] dolfinx', dolfinx.__version__, '| torch', torch.__version__, '| numpy', numpy.__version__)"
	@touch $@

# ---------------------------------------------------------------- main commands
# One joint FEM against the surrogate, the paper's gravity and grasp gestures, one coarse
# whole-finger FEM against the predictor: PNGs + summary.{json,md} + a table (apps/demo.py).
# Its FEM runs on the 1.8 mm reference's meshes (the joint on PAPER's 1.8 mm, the finger on
# 4 mm tetrahedra, both displacement), never on the production hexahedra, and is compared
# with the 1.8 mm reference surrogate (results/surrogate/h1.8/); the gripper's gestures use
# the default, production one.
demo: $(SETUP) ## the main job (~2 min): joint FEM (1.8 mm) vs surrogate, gestures, coarse finger FEM vs predictor -> results/demo/
	$(PY) -m apps.demo --out results/demo

# Two workers, one test file each at a time (--dist loadfile keeps a file's module
# fixtures, e.g. the Slurm cluster and the coarse FEM solvers, on one worker): 13.4 min of
# pytest, 14.0 min with set-up (apt packages present), in a fresh clone on this 2-core machine
# with nothing beside (1,519 tests); 23.7 min beside a one-core FEM job.
test: $(SETUP) ## the test suite (coarse FEM, small data, Slurm; ~14 min with set-up)
	$(PY) -m pytest -q -ra -n 2 --dist loadfile --durations=15

# ---------------------------------------------------------------- fem (issue 2)
# Every module of fem/ and its sub-packages (mesh, physics, solvers, cli, studies; docs/packages.md).
FEM_CODE := $(wildcard fem/*.py fem/*/*.py)
bench-fem: results/bench/fem.json ## FEM timings of the production discretisation (hex2:3 mixed) and of PAPER (1.8 mm) -> results/bench/fem.json
results/bench/fem.json: $(TIMES) $(FEM_CODE) | $(SETUP)
	$(PY) -m fem.studies.bench_joint --out $@

# Checked against the committed finger cases, so on their discretisation (PAPER_MESH).
bench-finger: results/bench/finger.json ## whole-finger FEM timings on the committed cases' 1.8 mm mesh, 4 gestures on one core (idle machine, ~18 min) -> results/bench/finger.json
results/bench/finger.json: $(TIMES) $(FEM_CODE) | $(SETUP)
	$(PY) -m fem.studies.bench_finger $(PAPER_MESH) --out $@

# The families are solved in the mixed u-p formulation: volumetric locking of displacement P2
# at nu = 0.49 is the largest single effect (make mesh-causes). The swept hexahedra hex2,
# hex3, hex4 (nested) give the Richardson reference; hex4 (150,561 Q2 nodes) needs ~13 GB on
# one core and starts from hex2's answer (--seed-from). The production candidate hex2:3
# (graded in x-y) is judged against it (docs/decisions.md §9). MESH_STUDY_HOURS=0 re-analyses.
MESH_STUDY_HOURS ?= 3
STUDY_PRODUCTION ?= hex2:3
mesh-study: | $(SETUP) ## 8 loads x (mixed hexahedra hex2, hex3, hex4 + production hex2:3 + paper 1.8 mm) + Richardson (one core, ~13 GB, hours; resumes) -> results/fem/mesh_study.json
	nice $(PY) -m fem.studies.mesh_study --formulation mixed --meshes hex2 hex3 hex4 --production $(STUDY_PRODUCTION) \
	  --production-formulation mixed --seed-from hex2 --out results/fem/mesh_study.json --work results/fem/joint_cases \
	  --max-hours $(MESH_STUDY_HOURS)

# Its committed study judged the 1.8 mm displacement mesh, the production one then.
mesh-study-tet: | $(SETUP) ## the same on the mixed sqrt-2 tetrahedral family 3.394:1.697 .. 1.2:0.6, judging PAPER's 1.8 mm (2 ranks, many hours; resumes) -> results/fem/mesh_study_tet.json
	$(MPIRUN) -n 2 $(PY) -m fem.studies.mesh_study --formulation mixed --production 1.8 --production-formulation displacement \
	  --out results/fem/mesh_study_tet.json --work results/fem/joint_cases --max-hours $(MESH_STUDY_HOURS)

MESH_CAUSES_HOURS ?= 3
mesh-causes: | $(SETUP) ## what limits the joint's mesh convergence: formulation, quadrature, penalty, wall elements at 8 loads, one factor at a time (one core, hours; resumes) -> results/fem/mesh_causes.{json,md}
	nice $(PY) -m fem.studies.mesh_causes --work results/fem/joint_cases --out results/fem/mesh_causes.json --max-hours $(MESH_CAUSES_HOURS)

materials: results/fem/materials.json ## each hyperelastic law's FEM against its closed form on homogeneous deformations (minutes) -> results/fem/materials.json
results/fem/materials.json: $(TIMES) fem/physics/materials.py fem/studies/materials_check.py contract/joint.py | $(SETUP)
	$(PY) -m fem.studies.materials_check --out $@

joint-outline: results/fem/joint_outline.json ## how far the pressurised cells bulge beyond the predictor's outline band (free joint, production mesh, ~3 min); prints the joint file's [outline] table
results/fem/joint_outline.json: $(TIMES) $(FEM_CODE) | $(SETUP)
	$(PY) -m fem.studies.joint_outline --out $@

self-contact: results/fem/self_contact.json ## min wall gap over the box corners, on the committed data's 1.8 mm mesh
results/fem/self_contact.json: $(TIMES) $(FEM_CODE) | $(SETUP)
	$(PY) -m fem.studies.self_contact $(PAPER_MESH) --out $@

validation: results/fem/validation.json ## FEM vs exact elastica: cantilever alpha<=10, roll-up to 2 pi
results/fem/validation.json: $(TIMES) $(FEM_CODE) | $(SETUP)
	$(PY) -m fem.studies.validation table --out $@

joint-render: results/fem/joint.png ## pyvista render of the joint, undeformed + deformed, on the committed data's 1.8 mm mesh
results/fem/joint.png: $(TIMES) $(FEM_CODE) | $(SETUP)
	$(PY) -m fem.cli.render $(PAPER_MESH) --out $@

# ---------------------------------------------------------------- campaign (issue 3)
# (section owned by workflow/)
# The datasets are resumable: each campaign stops cleanly after DATASET_HOURS (exit 3,
# which stops make) and `make dataset` again resumes from the shards. Train and held-out
# sets use different seeds; the held-out set uses 16-sample units (more independent walks
# for its 256 samples); ranks = DATASET_RANKS groups of one rank. DATA_MESH and DATA_TAG
# choose the discretisation and the folders' suffix: by default the production walks
# results/data/{heldout,train} (hex2:3 mixed, the held-out walk first); the paper-fidelity
# reference walks results/data/{heldout,train}_h1.8 resume with
#   make dataset DATA_MESH="--mesh-size 1.8 --formulation displacement" DATA_TAG=_h1.8
DATASET_RANKS ?= 2
DATASET_HOURS ?= 2
DATA_MESH     ?= $(PROD_MESH)
DATA_TAG      ?=
TRAIN_DATA    := results/data/train$(DATA_TAG)
HELDOUT_DATA  := results/data/heldout$(DATA_TAG)
CAMPAIGN      := nice $(MPIRUN) -n $(DATASET_RANKS) $(PY) -m workflow.campaign
SMOKE_DIR     := build/dataset-smoke

dataset: | $(SETUP) ## FEM datasets on the production discretisation (hex2:3 mixed): results/data/heldout (256, seed 2) then train (2560, seed 1); DATASET_HOURS per run; re-run resumes
	$(CAMPAIGN) --samples 256 --seed 2 --unit-size 16 $(DATA_MESH) --out $(HELDOUT_DATA) --max-hours $(DATASET_HOURS)
	$(CAMPAIGN) --samples 2560 --seed 1 $(DATA_MESH) --out $(TRAIN_DATA) --max-hours $(DATASET_HOURS)
	$(PY) -m workflow.dataset verify $(HELDOUT_DATA) --require-complete
	$(PY) -m workflow.dataset verify $(TRAIN_DATA) --require-complete --mirror 2

# Why the production train walk's failed samples failed (issue 55 §2): each one's load path
# from zero probed at every converged step for negative eigenvalues of the stiffness, its
# lowest eigenvalue and the closed valley pairs (workflow.stability; one core).
failed-samples: | $(SETUP) ## probe the production train walk's failed samples' load paths for a limit point or a contact change (one core, ~1 h) -> results/fem/stability_train.json
	nice $(PY) -m workflow.stability $(TRAIN_DATA)

# The failed samples re-solved (workflow.resolve): the campaign's own solver and mesh, only
# the path finer (steps of 0.005 from s = 0.8, 24 Newton iterations a step); each solved
# sample is stored in its unit's shard and the manifest rebuilt (resumes; exit 3 while some
# stay failed), then the walk is verified.
resolve-samples: | $(SETUP) ## re-solve the production train walk's failed samples on a finer load path and store them (one core, ~1 h; resumes) -> results/data/train/, results/fem/resolved_train.json
	nice $(PY) -m workflow.resolve $(TRAIN_DATA) --max-hours $(DATASET_HOURS)
	$(PY) -m workflow.dataset verify $(TRAIN_DATA) --require-complete

# The held-out walk again on the finer joint mesh H:W = 1.697:0.849 (two P2 elements through
# the wall, 3x the nodes, displacement as the 1.8 mm reference walks): the reference data's
# discretisation change over the load distribution the surrogate is judged on, and the
# reference surrogate (results/surrogate/h1.8/) against it. Resumes.
FINE_MESH    := --mesh-size 1.697 --wall-mesh-size 0.849 --formulation displacement
FINE_HELDOUT := results/data/heldout_h1.697w0.849
# The paper-fidelity reference: the 1.8 mm walks and the surrogate trained on them.
REF_TRAIN     := results/data/train_h1.8
REF_HELDOUT   := results/data/heldout_h1.8
REF_SURROGATE := results/surrogate/h1.8
dataset-fine: | $(SETUP) ## held-out walk on the finer mesh 1.697:0.849 (~1.7 h on 2 cores; resumes) + its comparison -> results/fem/heldout_mesh.json
	$(CAMPAIGN) --samples 256 --seed 2 --unit-size 16 $(FINE_MESH) --out $(FINE_HELDOUT) --max-hours $(DATASET_HOURS)
	$(MAKE) fine-compare

fine-compare: | $(SETUP) ## compare what the finer-mesh held-out walk holds so far with the 1.8 mm one -> results/fem/heldout_mesh.json, results/surrogate/h1.8/heldout_fine.json
	$(PY) -m workflow.dataset verify $(FINE_HELDOUT)
	$(PY) -m workflow.dataset compare $(REF_HELDOUT) $(FINE_HELDOUT) --out results/fem/heldout_mesh.json
	$(PY) -m surrogate.evaluate --model $(REF_SURROGATE)/improved.pt --data $(FINE_HELDOUT) --out $(REF_SURROGATE)/heldout_fine.json

# The production held-out walk against the 1.8 mm reference walk: the reference data's own
# discretisation error over the loads the surrogate is judged on, and the reference
# surrogate against it.
production-compare: | $(SETUP) ## compare the 1.8 mm held-out walk with the production one -> results/fem/heldout_production.json, results/surrogate/h1.8/heldout_production.json
	$(PY) -m workflow.dataset verify results/data/heldout --require-complete
	$(PY) -m workflow.dataset compare $(REF_HELDOUT) results/data/heldout --out results/fem/heldout_production.json
	$(PY) -m surrogate.evaluate --model $(REF_SURROGATE)/improved.pt --data results/data/heldout --out $(REF_SURROGATE)/heldout_production.json

dataset-smoke: | $(SETUP) ## tiny 2-rank campaign on the coarse 4 mm mesh (mixed) into build/dataset-smoke, verified
	rm -rf $(SMOKE_DIR) && mkdir -p build
	$(MPIRUN) -n 2 $(PY) -m workflow.campaign --samples 8 --seed 3 --unit-size 4 --mesh-size 4 \
	  --out $(SMOKE_DIR) --progress-every 10
	$(PY) -m workflow.dataset verify $(SMOKE_DIR) --require-complete --mirror 1
	$(PY) -m workflow.dataset info $(SMOKE_DIR)

bench-campaign: results/bench/campaign.json ## campaign samples/h on 1 and 2 ranks, harvested vs fresh, on the 1.8 mm reference mesh -> results/bench/campaign.json
results/bench/campaign.json: $(TIMES) workflow/campaign.py workflow/bench_campaign.py fem/solvers/joint.py | $(SETUP)
	nice $(PY) -m workflow.bench_campaign $(PAPER_MESH) --mpirun "$(MPIRUN)" --data $(REF_TRAIN) $(REF_HELDOUT) --out $@

# ---------------------------------------------------------------- surrogate (issue 4)
# (section owned by surrogate/)
# The production surrogate (issue 55 stage 1) in SURROGATE_DIR, trained on the production
# walks: the sweep on the complete data (bounded, resumable), the config it chose (the
# improved config with SURROGATE_SET, docs/decisions.md §9) and the paper's, the KNN
# baseline, and the learning curve beside the 1.8 mm reference's. The 1.8 mm reference models
# (results/surrogate/h1.8/) rebuild with
#   make train sweep learning-curve DATA_TAG=_h1.8 SURROGATE_DIR=results/surrogate/h1.8 SURROGATE_SET= LC_REFERENCE=
SURROGATE_DIR  ?= results/surrogate
SURROGATE_CODE := surrogate/data.py surrogate/model.py surrogate/train.py surrogate/evaluate.py \
                  workflow/shards.py
# The sweep's choice on the production data (results/surrogate/sweep/, docs/decisions.md §9):
# the lowest validation error among the variants that meet issue 55's targets without
# slowing the predictor, symmetric 4 x 64 (validation 0.0142 mm; symmetric 4 x 128's 0.0098 mm
# costs a 61 x 61 atlas 1.3x).
SURROGATE_SET  ?= equivariant=false symmetric=true hidden=64,64,64,64
SWEEP_HOURS    ?= 2
LC_REFERENCE   ?= $(REF_SURROGATE)/learning_curve.json

train: $(SURROGATE_DIR)/metrics.json ## surrogates (paper, chosen improved) + KNN on the production data -> results/surrogate/

$(SURROGATE_DIR)/paper.pt $(SURROGATE_DIR)/improved.pt: $(SURROGATE_DIR)/%.pt: \
    $(TIMES) $(wildcard $(TRAIN_DATA)/manifest.json) $(SURROGATE_CODE) | $(SETUP)
	@mkdir -p $(@D)
	nice $(PY) -m surrogate.train --config $* $(if $(filter improved,$*),$(SURROGATE_SET:%=--set %)) --data $(TRAIN_DATA) --out $@

$(SURROGATE_DIR)/metrics.json: $(TIMES) $(SURROGATE_DIR)/paper.pt $(SURROGATE_DIR)/improved.pt \
    surrogate/knn.py $(wildcard $(HELDOUT_DATA)/manifest.json) | $(SETUP)
	$(PY) -m surrogate.evaluate --report --train-data $(TRAIN_DATA) --heldout $(HELDOUT_DATA) --dir $(SURROGATE_DIR)

sweep: | $(SETUP) ## the sweep's variants of the improved config on the production data (one core, bounded by SWEEP_HOURS, resumes) -> results/surrogate/sweep/
	@mkdir -p $(SURROGATE_DIR)
	nice $(PY) -m surrogate.sweep --data $(TRAIN_DATA) --heldout $(HELDOUT_DATA) --jobs 1 \
	  --dir $(SURROGATE_DIR)/sweep --max-hours $(SWEEP_HOURS)

learning-curve: | $(SETUP) ## held-out errors vs 100..1,600 and all train samples, with/without the Jacobian loss, 2nd seed at 400, beside the 1.8 mm curve (1 core, ~1.5 h idle; resumes) -> results/surrogate/learning_curve.{json,png}
	@mkdir -p $(SURROGATE_DIR)
	nice $(PY) -m surrogate.learning_curve --data $(TRAIN_DATA) --heldout $(HELDOUT_DATA) --repeat 400:1 \
	  --out $(SURROGATE_DIR)/learning_curve.json $(if $(LC_REFERENCE),--reference $(LC_REFERENCE))

bench-surrogate: results/bench/surrogate_cost.json ## the production surrogate's cost per query against the 1.8 mm reference's, batches of 1, 2 and 7,442 (~2 min) -> results/bench/surrogate_cost.json
results/bench/surrogate_cost.json: $(TIMES) surrogate/bench_cost.py $(REF_SURROGATE)/improved.pt results/surrogate/improved.pt | $(SETUP)
	$(PY) -m surrogate.bench_cost $(REF_SURROGATE)/improved.pt results/surrogate/improved.pt --out $@

# Multi-fidelity against fine-only training at equal FEM cost (issue 35 §3). Committed: the
# development stand-in on the 1.8 mm reference (coarse = the 1.8 mm train walk and its
# improved.pt, fine = the 1.697:0.849 held-out walk split 128/32/96, judged against the 1.8 mm
# learning curve), in results/surrogate/h1.8/; on new data pass MF_FINE/MF_HELDOUT.
MF_FINE    ?= $(FINE_HELDOUT)
MF_HELDOUT ?=
multifidelity: | $(SETUP) ## coarse surrogate + a learned fine-minus-coarse correction vs fine-only at equal CPU hours, on the 1.8 mm reference (1 core, ~15 min; resumes) -> results/surrogate/h1.8/multifidelity.{json,png}
	nice $(PY) -m surrogate.multifidelity --coarse $(REF_TRAIN) --coarse-model $(REF_SURROGATE)/improved.pt --fine $(MF_FINE) \
	  $(if $(MF_HELDOUT),--heldout $(MF_HELDOUT)) --reference-curve $(REF_SURROGATE)/learning_curve.json \
	  --out $(REF_SURROGATE)/multifidelity.json

# ---------------------------------------------------------------- predictor (issue 5)
# (section owned by predictor/)
# Joint model for the predictor: the committed production surrogate (`make train` makes it;
# the analytic stand-in only when asked for by name, PRED_JOINT=analytic). PRED_DIR and
# PRED_BENCH say where the predictor's artefacts go; the 1.8 mm reference's rebuild with
#   make gestures atlas atlas-reference atlas-reference-fine inverse bench-predictor \
#     PRED_JOINT=results/surrogate/h1.8/improved.pt PRED_DIR=results/predictor/h1.8 \
#     PRED_BENCH=results/bench/predictor_h1.8.json
# About 1.5 h on one core, measured piece by piece on the production surrogate: the contact NN
# 52 min (mostly its ramped labels), the gravity NNs 2 min and 1 min (one finger alone), the
# atlases with their references 25 min, the gestures, inverse cases and bench about 20 min.
PRED_JOINT ?= results/surrogate/improved.pt
PRED_DIR   ?= results/predictor
PRED_BENCH ?= results/bench/predictor.json
# The code every predictor artefact depends on: the model, the solvers, the networks and the
# training command (predictor's sub-packages, docs/packages.md).
PRED_CORE  := $(wildcard predictor/model/*.py predictor/solvers/*.py predictor/nn/*.py) predictor/cli/nn.py \
              predictor/defaults.py contract/grasp.py $(filter-out analytic,$(PRED_JOINT))

gestures: $(PRED_DIR)/gestures.json ## paper's gesture cases, grasps and NN curves -> results/predictor/
$(PRED_DIR)/gestures.json: $(TIMES) $(PRED_CORE) predictor/cli/figures.py $(PRED_DIR)/gravity_nn_paper.pt $(PRED_DIR)/gravity_nn.pt $(PRED_DIR)/contact_nn.pt | $(SETUP)
	nice $(PY) -m predictor.cli.figures --out $(PRED_DIR) --nn-dir $(PRED_DIR) --model $(PRED_JOINT)

$(PRED_DIR)/gravity_nn_paper.pt: $(TIMES) $(PRED_CORE) | $(SETUP) ## train the paper's gravity NN on one finger's equilibrium loss (75 epochs, ~1 min)
	@mkdir -p $(@D)
	nice $(PY) -m predictor.cli.nn --variant gravity-paper --model $(PRED_JOINT) --out $@

$(PRED_DIR)/gravity_nn.pt: $(TIMES) $(PRED_CORE) | $(SETUP) ## train the improved gravity NN on Newton labels of one finger alone (SiLU + L-BFGS; ~2 min: 20,000 labels 6 s, training 92 s)
	@mkdir -p $(@D)
	nice $(PY) -m predictor.cli.nn --variant gravity-improved --model $(PRED_JOINT) --out $@

$(PRED_DIR)/contact_nn.pt: $(TIMES) $(PRED_CORE) | $(SETUP) ## train the contact NN (state classifier, one head per state, two correction stages each) on 20,000 ramp-solver labels (~50 min)
	@mkdir -p $(@D)
	nice $(PY) -m predictor.cli.nn --variant contact --model $(PRED_JOINT) --out $@

bench-predictor: $(PRED_BENCH) ## predictor timings and residuals, torch.compile graphs (~10 min) -> results/bench/predictor.json
$(PRED_BENCH): $(TIMES) $(PRED_CORE) predictor/validation/bench.py $(PRED_DIR)/gravity_nn_paper.pt $(PRED_DIR)/gravity_nn.pt $(PRED_DIR)/contact_nn.pt | $(SETUP)
	$(PY) -m predictor.validation.bench --model $(PRED_JOINT) --nn-dir $(PRED_DIR) --graphs compile --out $@

# ---------------------------------------------------------------- grasp planning (issue 16)
# (section owned by predictor/)
ATLAS_OBJECTS := circle ellipse rectangle
ATLAS_JSON    := $(foreach o,$(ATLAS_OBJECTS),$(PRED_DIR)/atlas_$(o).json)
PLAN_CODE     := $(PRED_CORE) $(wildcard predictor/planning/*.py) predictor/cli/atlas.py predictor/artefacts.py

atlas: $(ATLAS_JSON) ## grasp atlas 61x61 of the three objects -> results/predictor/atlas_{circle,ellipse,rectangle}.{png,json}
$(PRED_DIR)/atlas_%.json: $(TIMES) $(PLAN_CODE) | $(SETUP)
	@mkdir -p $(@D)
	nice $(PY) -m predictor.cli.atlas --object $* --grid 61 --model $(PRED_JOINT) \
	  --plot $(PRED_DIR)/atlas_$*.png --out $@ --json

ATLAS_RAMP    := $(foreach o,$(ATLAS_OBJECTS),$(PRED_DIR)/ramp/atlas_$(o).json)
atlas-reference: $(ATLAS_RAMP) ## the atlases with every point ramped on its own (the sweep's reference, ~10 min) -> results/predictor/ramp/
$(PRED_DIR)/ramp/atlas_%.json: $(TIMES) $(PLAN_CODE) | $(SETUP)
	@mkdir -p $(@D)
	nice $(PY) -m predictor.cli.atlas --object $* --grid 61 --path ramp --model $(PRED_JOINT) --out $@ --json

atlas-reference-fine: $(PRED_DIR)/ramp_fine/atlas_rectangle.json ## the rectangle's reference ramp with 48 sub-steps instead of 12: its path resolution (~9 min) -> results/predictor/ramp_fine/
$(PRED_DIR)/ramp_fine/atlas_%.json: $(TIMES) $(PLAN_CODE) | $(SETUP)
	@mkdir -p $(@D)
	nice $(PY) -m predictor.cli.atlas --object $* --grid 61 --path ramp --ramp-steps 48 --model $(PRED_JOINT) --out $@ --json

# A benchmark, not a test: medians of wall times on this machine, with its load recorded
# (inverse.json's track.load_average_*); the tip cases and the track at one thread.
inverse: $(PRED_DIR)/inverse.json ## inverse pressures: hold the three objects, three tip targets, the 100-goal track -> results/predictor/inverse.{json,png}, track.png
$(PRED_DIR)/inverse.json: $(TIMES) $(ATLAS_JSON) $(PLAN_CODE) predictor/cli/inverse.py | $(SETUP)
	nice $(PY) -m predictor.cli.inverse --cases --model $(PRED_JOINT) --atlas-dir $(PRED_DIR) \
	  --out $@ --plot $(PRED_DIR)/inverse.png --track-plot $(PRED_DIR)/track.png \
	  --track-out $(PRED_DIR)/track.json --json

# Issue 60's closed loop alone (a benchmark): the fingertip along the 100-goal demo path
# across the reachable region and out of it, each goal warm-started from the last answer and
# verified through the forward equilibrium (predictor.planning.track) -> $(PRED_DIR)/track.{json,png},
# and inverse.json's `track` replaced by this run's (the three from one run, as make inverse's).
# Exit 1 (some goals unreachable, by design of the path) is its normal end.
track: $(PRED_DIR)/inverse.json | $(SETUP) ## closed-loop tip tracking, 100 goals in and out of reach, timed and verified -> results/predictor/track.{json,png}, inverse.json's track
	nice $(PY) -m predictor.cli.inverse --track demo --model $(PRED_JOINT) --out $(PRED_DIR)/track.json \
	  --plot $(PRED_DIR)/track.png --into $(PRED_DIR)/inverse.json; test $$? -le 1

# ---------------------------------------------------------------- calibration (issue 38)
# The calibration's code: the predictor's core and predictor/calibration/ (docs/packages.md).
CAL_CODE      := $(PRED_CORE) $(wildcard predictor/calibration/*.py) predictor/cli/calibrate.py
calibrate-recovery: results/calibration/recovery.json ## calibration on known truth: the fit recovers parameters from predictor observations, noise-free and 20 noisy seeds (~1 min) -> results/calibration/recovery.json
results/calibration/recovery.json: $(TIMES) $(CAL_CODE) | $(SETUP)
	@mkdir -p $(@D)
	$(PY) -m predictor.cli.calibrate recovery --out $@

# Issue 38 §3(b): the whole-finger FEM of a deliberately different finger (CAL_TRUTH: joints
# E x 1.15, the tip 20 % heavier, the mount turned 2 deg) at CAL_PRESSURES with gravity, all
# inside |P| <= 0.2 MPa; predictor.calibration.fem.PRESSURES is the same list
# (tests/test_calibration_fem.py checks). One core, niced, on the production joint mesh
# (CAL_MESH, hex2:3 mixed, the surrogate's data's): 168-1,360 s a case, about 25 min a case
# on half a core beside another FEM job; a converged case is skipped, so a killed run
# resumes. The truth cases are one finger alone (--no-plane; the calibration's problem is
# issue 56's other part). The 1.8 mm reference cases (results/calibration/fem_h1.8/, 15 min)
# are CAL_MESH= (the truth joint file's own mesh, 1.8 mm) CAL_FEM=results/calibration/fem_h1.8.
CAL_TRUTH     := results/calibration/truth/finger.toml
CAL_FEM       ?= results/calibration/fem
CAL_MESH      ?= $(PROD_MESH)
CAL_PRESSURES := 0.2,0.2;-0.2,0.15;0.15,-0.2;-0.15,-0.15;0,0;0.1,0.05;-0.1,0.2;0.05,-0.1

calibration-fem: | $(SETUP) ## whole-finger FEM of the calibration's true finger at 8 gravity pressure pairs on the production joint mesh (1 core, niced, ~2-3 h; resumes) -> results/calibration/fem/
	nice $(PY) -m fem.studies.finger_cases --finger $(CAL_TRUTH) --pressures "$(CAL_PRESSURES)" --no-plane $(CAL_MESH) --out $(CAL_FEM)

# The fit is judged as the observations' fit is (predictor.calibration.fit.judge): an
# untrusted one exits 1 and writes nothing (no --force here: a demo that stops trusting
# its fit should fail, not commit it). The committed cases' fit is trusted: reduced
# chi-square 0.004 for 24 degrees of freedom (rms 0.016 mm against the stated 0.3 mm).
calibrate-demo: results/calibration/calibration.json ## calibrate the paper's predictor on 4 FEM gestures of the true finger, predict the other 4 (~1 min; needs make calibration-fem) -> results/calibration/{calibration.json,heldout.png,calibrated.toml}
results/calibration/calibration.json: $(TIMES) $(CAL_CODE) $(CAL_TRUTH) $(wildcard $(CAL_FEM)/*.json) \
    results/calibration/recovery.json | $(SETUP)
	$(PY) -m predictor.cli.calibrate fem --fem $(CAL_FEM) --truth $(CAL_TRUTH) --pressures "$(CAL_PRESSURES)" \
	  --model $(PRED_JOINT) --recovery results/calibration/recovery.json --out $@

bench-calibrate: results/bench/calibrate.json ## median wall time of the 8-observation calibration, 5 runs (~1 min) -> results/bench/calibrate.json
results/bench/calibrate.json: $(TIMES) $(CAL_CODE) docs/examples/observations.json | $(SETUP)
	$(PY) -m predictor.cli.calibrate bench --observations docs/examples/observations.json --model $(PRED_JOINT) --out $@

# ---------------------------------------------------------------- finger validation (issue 14)
# The lone-finger cases of finger-fem are on PAPER_MESH, as the 1.8 mm reference surrogate
# they are validated with (validate-finger-h1.8); the production cases with the plane are
# finger-grid's and the free ones (*_hex2s3_plane.json), validated by validate-finger.
FINGER_FEM := results/validation/finger_fem
# They are one finger alone (the tools' default is the gripper, the plane X = 0 on: issue 56).
FINGER_CASES := $(PY) -m fem.studies.finger_cases $(PAPER_MESH) --no-plane --out $(FINGER_FEM)

finger-fem: | $(SETUP) ## whole-finger FEM, 18 validation cases of one finger alone on the committed 1.8 mm displacement mesh (2 processes, several hours; resumes) -> results/validation/finger_fem/
	@$(FINGER_CASES) --part 1/2 & a=$$!; $(FINGER_CASES) --part 2/2; b=$$?; wait $$a && exit $$b

# Issue 56 §2: the 49 gravity pairs of the 7 x 7 grid over [-0.3, 0.3]^2 MPa, each a
# fem.studies.finger_cases record on the production discretisation (the joint file's [mesh], hex2:3
# mixed) with the plane X = 0, $(FINGER_FEM)/gravity_P1_P2_hex2s3_plane.json + .png; a
# record that stands is skipped (whoever wrote it), so a killed run resumes, and the summary
# results/fem/finger_grid.json is rewritten after every case (FINGER_GRID_ARGS=--summary-only:
# rebuild it from the records without solving).
FINGER_GRID_ARGS ?=
finger-grid: | $(SETUP) ## whole-finger FEM with the plane X = 0 at the 49 gravity pressure pairs of a 7 x 7 grid over the box, production mesh (one process, niced, hours; resumes; FINGER_GRID_ARGS=--summary-only to only rebuild the summary) -> results/validation/finger_fem/gravity_*_hex2s3_plane.json, results/fem/finger_grid.json
	nice $(PY) -m fem.studies.finger_grid --cases $(FINGER_FEM) --out results/fem/finger_grid.json $(FINGER_GRID_ARGS)

# The FEM side of the grasp validation (issue 36 §3, fem/studies/grasp_cases.py, docs/fem-grasps.md):
# the paper's six grasps and ten atlas cases on the production discretisation (the joint
# file's [mesh], hex2:3 mixed), the plane X = 0 on; a converged case is skipped, so a killed
# run resumes. Never part of `make test` (tests/test_grasp_cases.py runs no grasp).
GRASP_FEM := results/validation/grasps_fem
grasp-fem: | $(SETUP) ## whole-finger FEM grasps: the paper's six + ten atlas cases on the production mesh, plane X = 0 (one process, niced, hours; resumes) -> results/validation/grasps_fem/
	nice $(PY) -m fem.studies.grasp_cases --out $(GRASP_FEM)

# The predictor side (issue 36 §3, predictor/validation/grasps.py): each FEM grasp of
# grasp-fem on the production discretisation (files <case>_hex2s3.json) against the
# predictor with the same finger, object, history, mu, W and plane; it never runs the FEM
# itself (hours): run `make grasp-fem` first.
GRASP_FIGURES := results/validation/grasps
validate-grasps: results/validation/grasps.json ## predictor against the FEM grasps of make grasp-fem (production mesh, ~1 min) -> results/validation/grasps.json + overlays in results/validation/grasps/
results/validation/grasps.json: $(TIMES) $(wildcard $(GRASP_FEM)/*_hex2s3.json) predictor/validation/grasps.py \
    predictor/validation/cases.py predictor/model/plot.py $(PRED_CORE) | $(SETUP)
	$(PY) -m predictor.validation.grasps --fem $(GRASP_FEM) --mesh hex2:3 --formulation mixed --model $(PRED_JOINT) \
	  --out $@ --figures $(GRASP_FIGURES)

# The predictor against the production-mesh finger cases with the plane X = 0 (issue 56 §3;
# the files *_hex2s3_plane.json of make finger-grid and the free cases), on the production
# surrogate; it never runs the FEM itself.
validate-finger: results/validation/finger.json ## predictor against the production-mesh finger FEM cases, plane X = 0 (8 cases: 36 CPU s, 2.7 min at load 4) -> results/validation/finger.json + overlays finger_*.png
results/validation/finger.json: $(TIMES) $(wildcard $(FINGER_FEM)/*_hex2s3_plane.json) predictor/validation/finger.py \
    predictor/validation/cases.py $(PRED_CORE) | $(SETUP)
	$(PY) -m predictor.validation.finger --fem $(FINGER_FEM) --mesh hex2:3 --formulation mixed --plane \
	  --model $(PRED_JOINT) --out $@ --figures results/validation

# The 1.8 mm reference: the lone-finger cases of finger-fem (solved first if missing) against
# the predictor on the 1.8 mm reference surrogate.
validate-finger-h1.8: results/validation/finger_h1.8.json ## predictor (tangent/cap kinematics) on the 1.8 mm reference surrogate against the 1.8 mm lone-finger FEM -> results/validation/finger_h1.8.json + overlays in finger_h1.8/
results/validation/finger_h1.8.json: $(TIMES) $(wildcard $(FINGER_FEM)/*.json) predictor/validation/finger.py $(PRED_CORE) \
    predictor/validation/cases.py $(REF_SURROGATE)/improved.pt | $(SETUP)
	$(MAKE) --no-print-directory finger-fem
	@mkdir -p results/validation/finger_h1.8
	$(PY) -m predictor.validation.finger --fem $(FINGER_FEM) --mesh 1.8 --formulation displacement \
	  --model $(REF_SURROGATE)/improved.pt --out $@ --figures results/validation/finger_h1.8

# ---------------------------------------------------------------- one joint file to a predictor (issue 37)
# (section owned by apps/pipeline.py) Render, the two campaigns, training, held-out errors and
# a three-joint gesture of JOINT into results/joints/<its name>/ (docs/pipeline.md); every
# stage resumes, so a killed or time-limited run (exit 3) is finished by running it again.
# The same through Slurm: JOINT=FILE sbatch workflow/slurm/pipeline.sbatch.
JOINT          ?=
BUDGET         ?= small
PIPELINE_RANKS ?= 2
PIPELINE_HOURS ?=
.PHONY: pipeline
pipeline: | $(SETUP) ## one joint file -> FEM data, surrogate, held-out errors, gesture: make pipeline JOINT=file.toml [BUDGET=small|full] -> results/joints/<name>/
	nice $(PY) -m apps.pipeline --joint "$(JOINT)" --budget "$(BUDGET)" --ranks $(PIPELINE_RANKS) \
	  $(if $(PIPELINE_HOURS),--max-hours $(PIPELINE_HOURS))

report: ## results/REPORT.md from the committed JSON artefacts
	$(PY) -m apps.report --out results/REPORT.md

clean: ## remove the venv and caches (keeps results/)
	rm -rf $(VENV) .pytest_cache build *.egg-info
