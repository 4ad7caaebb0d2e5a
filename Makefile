# Two entry points: `make sweep` (main job) and `make test`. Both build .venv first.
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python

.PHONY: install sweep lint test
install: $(VENV)/.installed

# Headless rendering (hopper_mjx.render): EGL with Mesa's software rasteriser, no display or GPU.
# The viewer's test (hopper_mjx.view) runs it on a virtual X display driven by scripted key presses.
RENDER_DEBS := libegl1 libopengl0 libgl1-mesa-dri xvfb xdotool
# ROS's own message definitions (.msg files only): tests compare our bags' definitions with them.
ROS_MSG_DEBS := ros-std-msgs ros-geometry-msgs ros-sensor-msgs ros-nav-msgs ros-rosgraph-msgs ros-visualization-msgs
SYSTEM_DEBS := $(RENDER_DEBS) $(ROS_MSG_DEBS)

$(VENV)/.installed: pyproject.toml
	@if command -v dpkg >/dev/null && ! dpkg -s $(SYSTEM_DEBS) >/dev/null 2>&1; then \
	  if [ "$$(id -u)" = 0 ]; then \
	    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends $(SYSTEM_DEBS) >/dev/null; \
	  else echo "note: rendering and the ROS tests need: sudo apt-get install $(SYSTEM_DEBS)"; fi; \
	fi
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e '.[test]'
	touch $@

sweep: install
	$(PY) -m hopper_mjx.sweep gravity

lint: install
	$(VENV)/bin/ruff check .

# Two processes: XLA compiles on one core, so while one compiles the other runs. The tests that
# measure wall-clock pacing or timing bounds then run alone. The longest files go first (tests/conftest.py);
# the slowest 25 setups and tests are listed at the end, so that order can be checked against each run, then how long
# each spent building programs (tests/build_time.py).
test: lint
	$(PY) -m pytest -q -n 2 --dist loadfile --no-loadscope-reorder -m "not serial" --durations=25
	$(PY) -m pytest -q -m serial
