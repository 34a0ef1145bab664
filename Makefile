# grasp_apso: convenience targets. Everything runs in .venv (made by scripts/setup.sh);
# no ROS install and no `source` step are needed.
.PHONY: setup test demo bench experiment clean distclean

# Set-up (quick when nothing changed): venv, ROS 2 Jazzy wheels, interfaces, package.
setup:
	@bash scripts/setup.sh

# The whole test suite (runs the set-up first).
test:
	@bash scripts/test.sh

# Plan a grasp through the real node.
demo: setup
	@if [ -f scripts/demo.sh ]; then bash scripts/demo.sh; \
	else echo "make demo: scripts/demo.sh is not written yet (plan a grasp through the ROS node)"; exit 1; fi

# Benchmarks in bench/ (planner speed, decode, node): scripts/bench.sh.
bench: setup
	@if [ -f scripts/bench.sh ]; then bash scripts/bench.sh; \
	else echo "make bench: scripts/bench.sh is not written yet (APSO vs PSO benchmark)"; exit 1; fi

# The paper's experiment (Table 3, APSO vs PSO, pyswarms peers, speed) -> docs/experiment/.
# EXPERIMENT_ARGS passes options, e.g. make experiment EXPERIMENT_ARGS="--seeds 5".
experiment: setup
	@MPLBACKEND=Agg .venv/bin/python -m grasp_apso.experiment $(EXPERIMENT_ARGS)

# Build outputs (the installed venv stays; `make distclean` removes it too).
clean:
	rm -rf build install log .pytest_cache *.egg-info
	find . -name __pycache__ -type d -not -path './.venv/*' -prune -exec rm -rf {} +

distclean: clean
	rm -rf .venv
