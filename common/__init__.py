"""Vocabulary every layer of rollcam shares: the exception tree, value parsers, lifecycle helpers."""
