"""Shared fixtures. Tests mirror the packages: tests/data_gen, tests/aicalib_tf."""

import os

os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "2")
