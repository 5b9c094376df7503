# conveyor_twin: set up, run, test. Everything lives in .venv and build/; no ROS install needed.
#   make setup                 build .venv (idempotent; seconds when nothing changed)
#   make run ARGS='--mode fast'   setup, then conveyor-twin run $(ARGS)
#   make test [PYTEST_ARGS=...]   setup, then the whole pytest suite
#   make clean                 remove .venv, build/ and caches (the next setup starts from scratch)

VENV := .venv
ARGS ?=
PYTEST_ARGS ?=

.PHONY: setup run test clean

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

clean:
	rm -rf $(VENV) build install log .pytest_cache *.egg-info
	find . -name __pycache__ -type d -prune -not -path './.git/*' -exec rm -rf {} +
