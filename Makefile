# Both README commands set everything up first (idempotent; seconds when already done).
PY := .venv/bin/python

.PHONY: setup run test assets benchmark doctor

setup:
	@bash scripts/setup.sh

run: setup
	@$(PY) scripts/main.py

test: setup
	@$(PY) -m pytest -q

assets: setup
	@$(PY) scripts/build_assets.py

benchmark: setup
	@$(PY) scripts/benchmark.py

doctor: setup
	@$(PY) -m ms_construction.doctor
