# flexmb — developer entry points.
#
#   make setup   create .venv/, install flexmb (editable, all extras) and build flexmb_msgs and tf2_msgs into it
#   make demo    run the demo (DEMO_CMD, overridable: make demo DEMO_CMD=...)
#   make test    run the test suite on a random ROS_DOMAIN_ID, DDS discovery on localhost only
#   make bench   run the benchmarks
#   make clean / distclean
#
# `setup` is idempotent: stamp files under .venv/ record what was installed, so a second run
# with nothing changed does nothing. Edit pyproject.toml -> dependencies are reinstalled;
# edit msgs/ -> flexmb_msgs is rebuilt; edit ros/tf2_msgs/ -> tf2_msgs is rebuilt.

SHELL := /bin/bash
.SHELLFLAGS := -euo pipefail -c
.DELETE_ON_ERROR:
.DEFAULT_GOAL := help
MAKEFLAGS += --no-builtin-rules
comma := ,

PYTHON ?= python3.11
VENV := $(CURDIR)/.venv
PY := $(VENV)/bin/python
EXTRAS := dev,ros,ros-build,record,viz,bench,cluster
# rosidl interface packages built into the venv: flexmb_msgs (msgs/) and tf2_msgs (ros/tf2_msgs/, TFMessage
# only: not on PyPI, needed for a live /tf)
interface_src = $(1)/CMakeLists.txt $(1)/package.xml $(sort $(wildcard $(1)/msg/*.msg $(1)/srv/*.srv))
MSGS_SRC := $(call interface_src,msgs)
TF2_MSGS_SRC := $(call interface_src,ros/tf2_msgs)

# The Stewart twin end to end: the node and the command player as two processes on DDS (real
# time, Δt = 1 ms, the 20 s appendix trajectory), recorded to MCAP, then shown in rerun (an .rrd).
# Flexible frame legs (1 cubic element each) on the truss platform; the bar-leg twin:
# make demo DEMO_SCENE=scenes/stewart_platform_bars.yaml
DEMO_SCENE ?= scenes/stewart_platform_1el_truss.yaml
DEMO_CMD ?= rm -rf build/demo/bag && $(VENV)/bin/flexmb demo $(DEMO_SCENE) --mcap build/demo/bag --out build/demo \
	&& $(VENV)/bin/flexmb view build/demo/bag --rrd build/demo/stewart.rrd
PYTEST_ARGS ?=

# Environment of every recipe. DDS discovery never leaves the machine (the discovery range is the
# only localhost switch this ROS 2 honours); one BLAS thread; a writable numba cache.
export ROS_AUTOMATIC_DISCOVERY_RANGE := LOCALHOST
export OPENBLAS_NUM_THREADS := 1
export NUMBA_CACHE_DIR := $(CURDIR)/.cache/numba
export PYTHONUNBUFFERED := 1

.PHONY: help setup test demo bench clean distclean

help:
	@sed -n '3,8p' $(firstword $(MAKEFILE_LIST)) | sed 's/^# \{0,1\}//'

setup: $(VENV)/.stamp-msgs $(VENV)/.stamp-tf2-msgs

$(PY):
	$(PYTHON) -m venv $(VENV)

# Python dependencies: reinstalled when pyproject.toml changes.
$(VENV)/.stamp-deps: pyproject.toml | $(PY)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[$(EXTRAS)]'
	touch $@

# $(call build_interfaces,SOURCE_DIR,BUILD_DIR,IMPORT_CHECK): a rosidl interface package generated, built and
# installed into the venv prefix from an empty build directory (the recipe of a stamp rule below).
define build_interfaces
	rm -rf $(2)
	mkdir -p $(2)
	AMENT_PREFIX_PATH=$(VENV) cmake -S $(1) -B $(2) -Wno-dev \
	  -DCMAKE_PREFIX_PATH=$(VENV) -DCMAKE_INSTALL_PREFIX=$(VENV) \
	  -DPython3_EXECUTABLE=$(PY) -DCMAKE_BUILD_TYPE=Release >$(2)/flexmb-configure.log 2>&1 \
	  || { cat $(2)/flexmb-configure.log; exit 1; }
	cmake --build $(2) -j2 >$(2)/flexmb-build.log 2>&1 || { cat $(2)/flexmb-build.log; exit 1; }
	cmake --install $(2) >$(2)/flexmb-install.log 2>&1 || { cat $(2)/flexmb-install.log; exit 1; }
	cd / && $(PY) -c '$(3)'
	@echo "$(1) installed into $(VENV)"
	touch $@
endef

# flexmb_msgs, rebuilt whenever msgs/ or the dependencies change.
$(VENV)/.stamp-msgs: $(MSGS_SRC) $(VENV)/.stamp-deps
	$(call build_interfaces,msgs,$(CURDIR)/build/msgs,from flexmb_msgs.msg import ActuatorCommand$(comma) ActuatorState$(comma) TwinStatus)

# tf2_msgs (TFMessage), rebuilt whenever ros/tf2_msgs/ or the dependencies change.
$(VENV)/.stamp-tf2-msgs: $(TF2_MSGS_SRC) $(VENV)/.stamp-deps
	$(call build_interfaces,ros/tf2_msgs,$(CURDIR)/build/tf2_msgs,from tf2_msgs.msg import TFMessage)

test: setup
	domain=$$(( RANDOM % 200 + 1 )); echo "ROS_DOMAIN_ID=$$domain"; \
	ROS_DOMAIN_ID=$$domain $(PY) -m pytest -q $(PYTEST_ARGS)

demo: setup
	mkdir -p build
	$(DEMO_CMD)

bench: setup
	$(PY) benchmarks/run_all.py

clean:
	rm -rf build .cache

distclean: clean
	rm -rf $(VENV)
