"""Paired GS/RS datasets with exact labels: plan, render on any executor, write YOLO + COCO + a card.

``build_dataset(DatasetConfig(...), out_dir)`` is the Python entry point; ``rollcam dataset`` the command.
"""

from __future__ import annotations

from .build import BuildResult, build_dataset
from .footage import FootageConfig
from .plan import DatasetConfig, LabelPolicy, Sample, Task, make_plan, sample_uri, subset_name

__all__ = ["BuildResult", "DatasetConfig", "FootageConfig", "LabelPolicy", "Sample", "Task", "build_dataset",
           "make_plan", "sample_uri", "subset_name"]
