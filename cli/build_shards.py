"""``eosp build-shards ...``: the command line goes unparsed to :mod:`eosp.jobs.build_shards` (its own flags and
--help)."""

from __future__ import annotations

import argparse


def cmd_build_shards(ns: argparse.Namespace, rest: list[str]) -> int:
    from eosp.jobs.build_shards import main as build_main

    return build_main(rest, prog="eosp build-shards")
