"""Reproducible studies: the source paper's online-model-updating case study (``study paper``)."""

from fresco_bridge.study.cli import add_study_parser, study_command

__all__ = ["add_study_parser", "study_command"]
