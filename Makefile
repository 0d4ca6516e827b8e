# mrslam: `make demo` runs the main job, `make test` runs every test. Both set up .venv first.
PYTHON ?= python3.11
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
OUT    ?= runs/demo
DATA   ?= ../shared/data

.PHONY: venv demo mrclam test bench sample-bag clean

venv: $(STAMP)

# ROS 2 Jazzy comes from PyPI wheels; tf2_msgs is not among them and is generated with the
# wheels' rosidl generators (needs cmake, make and a C compiler) into $(VENV)/ros_interfaces,
# made importable by $(VENV)/lib/python3.11/site-packages/mrslam_interfaces.pth (see mrslam_ros/env.py).
INTERFACES := $(wildcard mrslam_ros/interfaces/*/package.xml mrslam_ros/interfaces/*/CMakeLists.txt mrslam_ros/interfaces/*/msg/*.msg)
# uv installs the same releases as pip (compared package by package) in a quarter of pip's 108 s
# here; pip remains the fallback where uv cannot be had or fails. uv leaves the bytecode to the
# first import, which the demo's six node processes would each do at once: it is compiled here (all
# but the packages' own test suites), beside the interfaces' build (30 s for both, 37 s in turn).
EXTRAS := .[ros,rosgen,test,baselines,view]
$(STAMP): pyproject.toml scripts/build_interfaces.sh $(INTERFACES)
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	( $(PY) -m pip install --quiet uv \
	  && $(VENV)/bin/uv pip install --quiet --python $(PY) -e "$(EXTRAS)" ) \
	|| ( echo "uv failed; installing with pip"; $(PY) -m pip install --quiet --upgrade pip \
	  && $(PY) -m pip install --quiet -e "$(EXTRAS)" )
	site="$$($(PY) -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')"; \
	( $(PY) -m compileall -q -j 0 -x '/tests?/' "$$site" > /dev/null || true ) & \
	scripts/build_interfaces.sh $(VENV) && wait
	touch $(STAMP)

# The main job: a simulated team of 3 robots exploring the office for 120 s, as separate ROS 2
# processes (simulator, a stereo frontend per robot, the central SLAM node, exploration), recorded
# into $(OUT)/bag; writes the run folder $(OUT). A previous run folder is moved aside first.
demo: venv
	@if [ -e $(OUT) ]; then rm -rf $(OUT).previous && mv $(OUT) $(OUT).previous; fi
	$(VENV)/bin/mrslam demo --out $(OUT)

# The joint filter on real multi-robot data (UTIAS MR.CLAM dataset 6 in ../shared/data).
mrclam: venv
	$(VENV)/bin/mrslam mrclam $(DATA)/mrclam/dataset6 --out runs/mrclam

# Two passes: the tests that run in one process (and short graphs) on both cores, then the live
# multi-process team runs alone, since they run against the wall clock and need the cores to
# themselves (marker `live`, pyproject.toml). The first pass hands out whole modules, those with a
# slow test first (test/conftest.py), so that no minute-long module starts when the rest is done.
test: venv
	$(PY) -m pytest -q --durations=15 -n 2 --dist loadfile --no-loadscope-reorder -m "not live"
	$(PY) -m pytest -q --durations=15 -m live

bench: venv
	$(VENV)/bin/mrslam bench filter --out runs/bench

clean:
	rm -rf $(VENV) runs build *.egg-info

# Re-record bags/sim2_small (the replay tests' recording): a 2-robot, 20 s run in the small world.
sample-bag: venv
	rm -rf build/sim2_small
	$(VENV)/bin/mrslam demo --robots 2 --seconds 20 --world small --out build/sim2_small
	rm -rf bags/sim2_small/bag && mkdir -p bags/sim2_small
	cp -r build/sim2_small/bag build/sim2_small/slam.yaml bags/sim2_small/
	sed -i "s#^output_dir:.*#output_dir: ''#; s#^checkpoint:.*#checkpoint: ''#" bags/sim2_small/slam.yaml
