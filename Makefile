# Two commands a new user needs: `make serve` and `make test`.
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
HOST ?= 127.0.0.1
PORT ?= 8000
DATA_DIR ?= ../shared/data
export MOTION_DATA_DIR ?= $(DATA_DIR)

.PHONY: setup serve test lint unit clean

$(PY):
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip

# Serving needs no torch; tests and training do.
$(VENV)/.serve: pyproject.toml | $(PY)
	$(PY) -m pip install -q -e ".[serve]"
	touch $@

# bpy (the fbx extra) has wheels for CPython 3.11 only: elsewhere the FBX tests skip.
$(VENV)/.dev: pyproject.toml | $(PY)
	$(PY) -m pip install -q -e ".[serve,train,dev,client]"
	$(PY) -m pip install -q -e ".[fbx]" \
		|| echo "bpy (the fbx extra) did not install on this Python: the FBX tests will skip" >&2
	touch $@ $(VENV)/.serve

setup: $(VENV)/.dev

serve: $(VENV)/.serve
	$(PY) -m service --host $(HOST) --port $(PORT)

lint: $(VENV)/.dev
	$(PY) -m ruff check .
	$(PY) -m ruff format --check .

test: $(VENV)/.dev
	$(PY) -m ruff check .
	$(PY) -m ruff format --check .
	$(PY) -m pytest -q

clean:
	rm -rf $(VENV) .pytest_cache .ruff_cache

# The image we ship is the image we test. `make image` builds motion-style:latest (and, where
# no registry answers, its base from Debian's packages, plus nginx and Prometheus for compose;
# deploy/image/build.sh). `make image-test` (CI runs it after `make test`) first installs
# docker.io, docker-compose and debootstrap with apt and starts dockerd where they are
# missing, then drives the container and the compose stack over HTTP (tests/image).
# `make image-fbx` builds motion-style:fbx, the same with the fbx extra (Blender, +0.9 GB);
# image-test builds and tests it too.
.PHONY: image image-fbx image-test
image:
	deploy/image/build.sh

image-fbx:
	EXTRAS="serve fbx" IMAGE=motion-style:fbx deploy/image/build.sh

image-test: $(VENV)/.dev
	deploy/image/ensure-docker.sh
	EXTRAS="serve fbx" IMAGE=motion-style:fbx deploy/image/build.sh >/dev/null
	base=$$(deploy/image/build.sh) && MOTION_IMAGE_BASE=$$base $(PY) -m pytest tests/image -v --durations=5

# Loopback load test of a fresh `python -m service`: 16 clients x 60 s on the GET endpoints,
# errors, p50/p95/p99 and RSS (the 8 x 5 s version runs in `make test`). LOAD_ARGS adds flags.
LOAD_ARGS ?=
.PHONY: load
load: $(VENV)/.dev
	$(PY) -m bench.load --clients 16 --duration 60 $(LOAD_ARGS)

# The translator: replays training/translator/schedule.json (CPU, hours), continuing from the
# stages checkpoints/translator.pt has finished (TRANSLATOR_ARGS="--from-scratch" to rebuild).
TRANSLATOR_ARGS ?=
.PHONY: train-translator
train-translator: $(VENV)/.dev
	$(PY) -m training.translator $(TRANSLATOR_ARGS)

# What a lent GPU machine needs to train the translator without the data folder, in
# cache/carry/ (13 MB: Bandai with float16 rotations, the pair alignments; training/carry.py).
.PHONY: carry-translator
carry-translator: $(VENV)/.dev
	$(PY) -m training.carry translator

# The same for the dance: cache/carry/dance_prepared.npz (18 MB: the prepared songs and
# dances in float16), for `python -m training.dance_schedule --device cuda --prepared ...`.
.PHONY: carry-dance
carry-dance: $(VENV)/.dev
	$(PY) -m training.carry dance

# The fast style networks, one per translator style, each distilled from the shipped
# translator's restyler for that style (training/fast_style.py; CPU, about an hour on 2
# cores), then ONNX + manifest entry "fast-bandai" with export-fast. Logs in runs/fast/.
# Extra flags: FAST_STYLE_ARGS="--max-steps 10".
FAST_STYLE_ARGS ?=
.PHONY: train-fast export-fast bench-fast show-styles
train-fast: $(VENV)/.dev
	$(PY) -m training.fast_style --all --threads 1 --jobs 2 $(FAST_STYLE_ARGS)

export-fast: $(VENV)/.dev
	$(PY) -m model_export.fast

# Both style families on motion from outside Bandai (CMU, Xia, CMU dance, other rigs' exports)
# judged by a style classifier of every real Bandai take (training/eval_foreign.py): the
# development half by default; EVAL_FOREIGN_ARGS="--half test" (or both) for more.
# Writes runs/eval/foreign-<half>.json; the judge is the committed training/foreign_judge.pt
# (EVAL_FOREIGN_ARGS=--pin-judge trains and replaces it). record-evaluations puts the test
# half's figures in the manifest.
# A studio's library: LIBRARY=path/to/library MODELS=models/NAME (the folder motion-style-train
# wrote) judges those models by a classifier of the library's own real takes, on the same
# halves; it writes runs/eval/NAME/, and record-evaluations with the same two records it there.
EVAL_FOREIGN_ARGS ?=
LIBRARY ?=
MODELS ?=
LIBRARY_ARGS = $(if $(LIBRARY),$(if $(MODELS),--library $(LIBRARY) --models-dir $(MODELS),\
	$(error LIBRARY needs MODELS, the models folder trained on it)))
.PHONY: eval-foreign game-invariants record-evaluations
eval-foreign: $(VENV)/.dev
	$(PY) -m training.eval_foreign $(LIBRARY_ARGS) $(EVAL_FOREIGN_ARGS)

# The game invariants' done-when figures on clips that chose none of their thresholds.
game-invariants: $(VENV)/.dev
	$(PY) -m training.game_invariants --json runs/eval/game-invariants.json

# The evaluations write JSON; this one step records their figures in the models' entries.
record-evaluations: $(VENV)/.dev
	$(PY) -m model_export.evaluations $(if $(LIBRARY_ARGS),\
	runs/eval/$(notdir $(abspath $(MODELS)))/foreign-test.json --models-dir $(MODELS),\
	$(wildcard runs/eval/foreign-test.json runs/eval/dance.json runs/eval/game-invariants.json))

bench-fast: $(VENV)/.dev
	$(PY) -m bench.bench_fast

# docs/styles.svg: a clip from outside Bandai sent to several styles by both families.
show-styles: $(VENV)/.dev
	$(PY) -m training.show_styles

# Dance (jacob2019 made to work): the alignment study writes training/dance_alignment.json;
# train-dance replays training/dance_schedule.json into checkpoints/dance.pt (each stage's
# checkpoint in checkpoints/dance-stages/, TensorBoard in runs/dance/), skipping the stages
# already finished; DANCE_ARGS="--from-scratch" retrains every stage. eval-dance: the generated beat test
# set (tracker F-measure, alignment to known beats vs shifted grids), every shared song, the
# held-out songs vs real dances, stalls over 10 minutes, genre recognition, foot sliding and
# contact score, AIST++ feature distances to real dance (development and test halves); and
# every fold: train-dance-fold1 replays the same schedule with fold 1's songs held out
# (training.dance.FOLDS) into checkpoints/dance-fold1.pt, which eval-dance exports to
# runs/eval/models-fold1 and judges on its own songs beside the shipped model, then pools.
DANCE_ARGS ?=
DANCE_FOLD1 := checkpoints/dance-fold1.pt
.PHONY: dance-alignment dance-tempo train-dance train-dance-fold1 export-dance eval-dance \
	judge-dance show-dance
dance-alignment: $(VENV)/.dev
	$(PY) -m training.dance_alignment --write

# Every shared song's tempo at the general and at its genre's level against its danced tempo
# (the genre centres fitted with the song left out).
dance-tempo: $(VENV)/.dev
	$(PY) -m training.dance_tempo --json runs/eval/dance_tempo.json

train-dance: $(VENV)/.dev
	$(PY) -m training.dance_schedule $(DANCE_ARGS)

train-dance-fold1: $(VENV)/.dev
	$(PY) -m training.dance_schedule --fold 1 --work checkpoints/dance-stages/fold1 \
		--out $(DANCE_FOLD1) $(DANCE_ARGS)

export-dance: $(VENV)/.dev
	$(PY) -m model_export.dance

eval-dance: $(VENV)/.dev
	rm -rf runs/eval/models-fold1
	$(PY) -m model_export.dance --checkpoint $(DANCE_FOLD1) --models-dir runs/eval/models-fold1 \
		--name dance-dwm-fold1
	$(PY) -m training.eval_dance --json runs/eval/dance.json --fold-models runs/eval/models-fold1
	$(PY) -m model_export.evaluations runs/eval/dance.json

# A trial judged as the rules in docs/dance_alignment.md judge one, without touching models/:
# DANCE_TRIAL=dir holding its fold-0 dance.pt and fold-1 dance-fold1.pt, exported to dir/models-*,
# then the held-out songs of both folds (12 seeds from DANCE_FIRST_SEED) and every shared song
# whole, into dir/judged.json
DANCE_TRIAL ?= runs/dance-trial
DANCE_FIRST_SEED ?= 0
judge-dance: $(VENV)/.dev
	rm -rf $(DANCE_TRIAL)/models-f0 $(DANCE_TRIAL)/models-f1
	$(PY) -m model_export.dance --checkpoint $(DANCE_TRIAL)/dance.pt --models-dir $(DANCE_TRIAL)/models-f0
	$(PY) -m model_export.dance --checkpoint $(DANCE_TRIAL)/dance-fold1.pt \
		--models-dir $(DANCE_TRIAL)/models-f1 --name dance-dwm-fold1
	MOTION_MODELS_DIR=$(DANCE_TRIAL)/models-f0 $(PY) -m training.eval_dance --held-out-only \
		--whole-songs --fold-models $(DANCE_TRIAL)/models-f1 --first-seed $(DANCE_FIRST_SEED) \
		--json $(DANCE_TRIAL)/judged.json

show-dance: $(VENV)/.dev
	$(PY) -m training.show_dance

# The translator: ONNX graphs, statistics, style table and the manifest entry
# "translator-bandai" from a copy of checkpoints/translator.pt (a training overwrites it).
# Extra flags: EXPORT_TRANSLATOR_ARGS="--checkpoint other.pt".
EXPORT_TRANSLATOR_ARGS ?=
.PHONY: export-translator
export-translator: $(VENV)/.dev
	$(PY) -m model_export.translator $(EXPORT_TRANSLATOR_ARGS)

# Speed tables, each measured in one run (ratios, not absolute numbers, are what compare):
# BVH parse/write, BVH reading against bvhio 1.5.4 on the same real files, retargeting (with
# every shared BVH's round trip, and beside motion/ as it was at BENCH_AGAINST), the fast
# networks in onnxruntime vs torch eager, the translator pipeline, dance generation for a
# 3-minute song, the translator and dance networks in onnxruntime vs torch eager, end-to-end
# HTTP latency (240/960/3,840 frames, end to end over the networks' own Server-Timing, cost
# vs length, throughput at 1-8 clients), an FBX transfer against the same character's GLB one
# (with bpy), 48 clients sending a 3,840-frame transfer at once
# (200 or 503 with Retry-After, peak RSS) and the loopback load test. Not part of `make test`.
BENCH_AGAINST ?= 836ff33
.PHONY: bench
bench: $(VENV)/.dev
	$(PY) -m bench.bench_motion
	$(PY) -m bench.bench_retarget --against $(BENCH_AGAINST)
	$(PY) -m bench.bench_fast
	$(PY) -m bench.bench_translator
	$(PY) -m bench.bench_dance
	$(PY) -m bench.bench_networks
	$(PY) -m bench.bench_http
	$(PY) -m bench.bench_fbx
	$(PY) -m bench.overload
	$(PY) -m bench.load --clients 16 --duration 60 $(LOAD_ARGS)

# The Blender add-on as a zip Blender installs (Edit > Preferences > Add-ons > Install...).
.PHONY: blender-addon
blender-addon: dist/motion_style.zip
dist/motion_style.zip: $(wildcard clients/blender/motion_style/*.py)
	$(PYTHON) -m clients.addon_zip $@
