# One command each: `make demo` (sets up .venv and runs a representative slice of the benchmark, about
# 1.5 minutes; `make demo-full` runs the whole suite of 2634 images and the four rig sequences, about
# 8 minutes plus about 2 for the rigs) and `make test`.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: setup demo demo-full test bench clean

# the compiled kernels (aicalib_tf/kernels.py) are rebuilt when their sources change; a failed build
# (no C compiler) leaves numba's JIT to compile them on first use, and is not retried until they change
KERNELS := $(VENV)/.kernels
KERNEL_SOURCES := aicalib_tf/kernels.py aicalib_tf/cnn/corner_map_kernels.py aicalib_tf/detect/corners/sampling.py \
                  $(wildcard aicalib_tf/detect/*_kernels.py aicalib_tf/detect/*/*_kernels.py)

$(STAMP): pyproject.toml
	test -d $(VENV) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[dev]"
	touch $(STAMP)

$(KERNELS): $(STAMP) $(KERNEL_SOURCES)
	$(PY) -m aicalib_tf.export --warm
	touch $(KERNELS)

setup: $(KERNELS)

demo: $(KERNELS)
	$(PY) -m aicalib_tf.evaluate --quick

demo-full: $(KERNELS)
	$(PY) -m aicalib_tf.evaluate

test: $(KERNELS)
	$(PY) -m pytest -q

bench: $(KERNELS)
	$(PY) -m aicalib_tf.evaluate --images tests/data/opencv_left --pattern 9x6 --degrade
	$(PY) benchmarks/datagen_accuracy.py
	$(PY) benchmarks/datagen_speed.py
	$(PY) benchmarks/refine_accuracy.py
	$(PY) benchmarks/model_compare.py

clean:
	rm -rf $(VENV) .pytest_cache reports aicalib_tf/_kernels_aot*
