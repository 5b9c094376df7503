# conveyor_twin: set up, run, test. Everything lives in .venv-<distro> and build/; no ROS install
# needed (ROS 2 comes from the PyPI wheels pinned in requirements/<distro>.txt).
#   make setup                 build .venv-jazzy (idempotent; seconds when nothing changed)
#   ROS_DISTRO=kilted make setup   the same for ROS 2 Kilted, in .venv-kilted
#   make setup PYTHON=python3.12   create the environment with Python 3.12 (default: 3.11)
#   make run ARGS='--mode fast'   setup, then conveyor-twin run $(ARGS)
#   make test [PYTEST_ARGS=...]   setup, then the whole pytest suite
#   make wheel                 binary wheel of ROS_DISTRO for PYTHON (default 3.11) into dist/
#   make wheels                every distro x Python this machine has an interpreter for
#   make clean                 remove every .venv*, build/, dist/ and caches (setup starts anew)
# .venv is a symlink to the environment the last setup built (see docs/platforms.md).

ROS_DISTRO ?= jazzy
VENV := .venv-$(ROS_DISTRO)
ARGS ?=
PYTEST_ARGS ?=
export ROS_DISTRO
ifdef PYTHON
export PYTHON
endif

.PHONY: setup run test wheel wheels clean

setup:
	@bash tools/setup_env.sh

run: setup
	$(VENV)/bin/conveyor-twin run $(ARGS)

# pytest exits 5 when it collected nothing: that is a failure, never a pass, and says so.
test: setup
	@$(VENV)/bin/python -m pytest $(PYTEST_ARGS); code=$$?; \
	if [ $$code -eq 5 ]; then \
		echo 'make test: pytest collected no tests (exit code 5); failing' >&2; fi; \
	exit $$code

# Wheels with the message package (tools/build_wheel.py, docs/platforms.md). They need no
# development environment: make setup's is reused when it matches, else one is built in build/.
wheel:
	python3 tools/build_wheel.py

wheels:
	python3 tools/build_wheel.py --distro all --python all

clean:
	rm -rf .venv .venv-* build dist install log .pytest_cache *.egg-info
	find . -name __pycache__ -type d -prune -not -path './.git/*' -exec rm -rf {} +
