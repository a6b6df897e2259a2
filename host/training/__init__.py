"""Training rollcam's own person detector (``rollcam train``) and the study's experiments (``rollcam study``).

Needs the ``train`` extra (torch, onnx). ``train(TrainConfig(...), out_dir)`` is the Python entry point of a run;
``run_study(SETTINGS[name], out_dir)`` that of the study. Modules here import torch at the top, so import them
only where training is asked for (the commands do, inside ``run``).
"""
