# Set-up and everyday commands. Both main targets create a local virtual environment first.
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin

.PHONY: demo test lint bench venv clean

$(BIN)/rollcam: pyproject.toml
	$(PY) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip
	$(BIN)/pip install -q -e ".[dev]"
	touch $(BIN)/rollcam

venv: $(BIN)/rollcam

demo: venv
	$(BIN)/rollcam demo

test: venv
	$(BIN)/ruff check .
	$(BIN)/python -m pytest -q

bench: venv
	$(BIN)/rollcam bench render --quick

clean:
	rm -rf $(VENV) build *.egg-info rollcam_out
