# Two commands do all set-up on a fresh Debian machine (root, Python 3.11, no GPU):
#   make demo   -- installs, then runs the end-to-end demo into outputs/
#   make test   -- installs, then runs the test suite
SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.vimsim-installed
SUDO := $(shell [ "$$(id -u)" = 0 ] || echo sudo)

.PHONY: demo test setup sysdeps lint bench clean

# Headless OpenGL: libEGL (glvnd) + Mesa's llvmpipe software rasteriser;
# Mono's C# compiler for the Unity export (simulator/export/unity/*.cs); glslang and
# spirv-cross for its overlay shader (VimsimOverlay.hlsl); headless Chromium for the
# browser tests (report, web export).
sysdeps:
	@if ! dpkg -s libegl1 libgl1-mesa-dri >/dev/null 2>&1; then \
		echo "installing Debian packages libegl1 libgl1-mesa-dri (headless EGL, llvmpipe)"; \
		$(SUDO) apt-get update -qq && \
		DEBIAN_FRONTEND=noninteractive $(SUDO) apt-get install -y -qq --no-install-recommends libegl1 libgl1-mesa-dri; \
	fi
	@# Mono C# compiler and runtime: the Unity export's C# runtime is compiled and checked
	@# against the Python EPOF in make test (tests/export/test_export_unity.py).
	@if ! dpkg -s mono-mcs mono-runtime >/dev/null 2>&1; then \
		echo "installing Debian packages mono-mcs mono-runtime (C# compiler for the Unity export check)"; \
		$(SUDO) apt-get update -qq && \
		DEBIAN_FRONTEND=noninteractive $(SUDO) apt-get install -y -qq --no-install-recommends mono-mcs mono-runtime; \
	fi
	@# glslang (HLSL -> SPIR-V) and spirv-cross (SPIR-V -> GLSL): the Unity export's overlay shader
	@# (VimsimOverlay.hlsl) is compiled and drawn against vimsim's renders in make test.
	@if ! dpkg -s glslang-tools spirv-cross >/dev/null 2>&1; then \
		echo "installing Debian packages glslang-tools spirv-cross (the Unity overlay shader check)"; \
		$(SUDO) apt-get update -qq && \
		DEBIAN_FRONTEND=noninteractive $(SUDO) apt-get install -y -qq --no-install-recommends glslang-tools spirv-cross; \
	fi
	@# Headless Chromium and its WebDriver: the browser tests of the study report and the web
	@# runtime (tests marked browser; WebGL2 through SwiftShader, no GPU, nothing downloaded).
	@if ! dpkg -s chromium chromium-driver >/dev/null 2>&1; then \
		echo "installing Debian packages chromium chromium-driver (headless browser tests)"; \
		$(SUDO) apt-get update -qq && \
		DEBIAN_FRONTEND=noninteractive $(SUDO) apt-get install -y -qq --no-install-recommends chromium chromium-driver; \
	fi

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	# CPU build of torch from this machine's disk (optional neural-flow backend).
	$(PY) -m pip install -q torch==2.13.0 || echo "note: torch==2.13.0 not installable here; torch tests will be skipped"
	$(PY) -m pip install -q -e '.[dev,ray]'
	touch $(STAMP)

setup: sysdeps $(STAMP)

demo: setup
	$(VENV)/bin/vimsim demo -o outputs/demo

# Both cores: one test file per worker at a time (module fixtures stay per file).
test: setup
	$(PY) -m pytest -q -n 2 --dist loadfile tests

lint: setup
	$(VENV)/bin/ruff check simulator tests bench

bench: setup
	for f in bench/*.py; do echo "== $$f"; $(PY) $$f || exit 1; done

clean:
	rm -rf $(VENV) outputs/demo tests/_out bench/_out
