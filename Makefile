# Set-up and everyday commands. Both main targets create a local virtual environment first: `make demo` installs
# rollcam with what its commands need, `make test` adds the test and lint tools (the `dev` extra).
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
PIP := $(BIN)/python -m pip
# OpenCV wheels that would sit beside rollcam's opencv-contrib-python-headless (a venv made before it was the
# dependency has one): two cv2 wheels overwrite each other's files, so the others go and contrib is laid anew.
OTHER_CV2 := opencv-python opencv-python-headless opencv-contrib-python

define one_opencv
	@if $(PIP) show $(OTHER_CV2) >/dev/null 2>&1; then \
	  echo "replacing $$($(PIP) freeze | grep -iE '^opencv-(contrib-)?python' | grep -v contrib-python-headless) \
	by opencv-contrib-python-headless"; \
	  for p in $(OTHER_CV2); do if $(PIP) show $$p >/dev/null 2>&1; then $(PIP) uninstall -q -y $$p; fi; done; \
	  $(PIP) install -q --force-reinstall --no-deps "$$($(PIP) freeze | grep -i '^opencv-contrib-python-headless==')"; \
	fi
endef

.PHONY: demo test test-kernel lint bench venv venv-dev modlib-ref clean

$(BIN)/python:
	$(PY) -m venv $(VENV)
	$(PIP) install -q --upgrade pip

$(VENV)/.installed: pyproject.toml setup.py sim/render/rollcam_shade.c emu/preload/rollcam_preload.c | $(BIN)/python
	$(PIP) install -q -e .
	$(one_opencv)
	touch $@

$(VENV)/.installed-dev: pyproject.toml setup.py sim/render/rollcam_shade.c emu/preload/rollcam_preload.c | $(BIN)/python
	$(PIP) install -q -e ".[dev]"
	$(one_opencv)
	touch $@ $(VENV)/.installed

venv: $(VENV)/.installed

venv-dev: $(VENV)/.installed-dev

demo: venv
	$(BIN)/rollcam demo

# Sony's modlib, the reference for the IMX500's input tensor path (tests/test_input_tensor.py): its wheel pins older
# numpy and OpenCV than rollcam's, so it is not installed; its pure-Python modules are unpacked beside the venv and
# the test imports them from there (they run on the venv's numpy and OpenCV). Without it (no registry) those tests
# skip, saying so; the download is tried again on the next run.
MODLIB := modlib==1.5.0
MODLIB_DIR := .modlib

$(MODLIB_DIR)/.unpacked: | $(BIN)/python
	rm -rf $(MODLIB_DIR) && mkdir -p $(MODLIB_DIR)/wheel
	($(PIP) download -q --no-deps -d $(MODLIB_DIR)/wheel "$(MODLIB)" \
	  && $(BIN)/python -m zipfile -e $(MODLIB_DIR)/wheel/*.whl $(MODLIB_DIR)/site && touch $@) \
	  || echo "$(MODLIB) could not be downloaded: the tests that compare with it will skip"

modlib-ref: $(MODLIB_DIR)/.unpacked

test: venv-dev modlib-ref
	$(BIN)/ruff check .
	$(BIN)/python -m pytest -q

# The kernel suite: Debian's stock kernel in QEMU drives the camera through vhci-hcd and uvcvideo (tests/guest.py;
# needs qemu-system-x86, busybox-static, socat, usbip, v4l-utils; the first run downloads the kernel package).
test-kernel: venv-dev
	$(BIN)/python tests/guest.py prepare
	$(BIN)/python -m pytest -q -m kernel

lint: venv-dev
	$(BIN)/ruff check .

bench: venv
	$(BIN)/rollcam bench render --quick

clean:
	rm -rf $(VENV) $(MODLIB_DIR) build *.egg-info rollcam_out
