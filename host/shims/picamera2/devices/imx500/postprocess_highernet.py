"""picamera2's decoder of HigherHRNet's outputs (``postprocess_higherhrnet``), for the grouping the AI Camera's
network does on chip (``network_postprocess=True``: per person slot and joint, the tag, the grid index and the
score; the emulated ``imx500_network_higherhrnet_coco`` sends these). Joints are taken in ``joint_order``; a
joint above ``detection_threshold`` joins the person whose mean tag is nearest (an optimal assignment on the tag
distance rounded, then the score) when that distance is under ``tag_threshold``, else it starts a person. Keypoints
come back as flat (x, y, score) x 17 lists in ``img_size`` pixels, each person's score the mean of its joints'
scores and its box (y0, x0, y1, x1) around the joints it has. The raw heatmap heads (``network_postprocess=False``)
are not decoded: the emulated sensor does not send them."""

from __future__ import annotations

from typing import Any

import numpy as np

default_joint_order = [0, 1, 2, 3, 4, 5, 6, 11, 12, 7, 8, 9, 10, 13, 14, 15, 16]


def _group(tag_k: np.ndarray, ind_k: np.ndarray, val_k: np.ndarray, width: int, joint_order: list[int],
           detection_threshold: float, max_num_people: int, tag_threshold: float) -> list[np.ndarray]:
    """People as (17, 4) arrays of x, y (output grid), score, tag; a joint not found is all zero."""
    from scipy.optimize import linear_sum_assignment

    people: list[np.ndarray] = []
    tags: list[list[float]] = []
    for joint in joint_order:
        keep = val_k[:, joint] > detection_threshold
        if not keep.any():
            continue
        idx = ind_k[keep, joint].astype(np.int64)
        found = np.stack([idx % width, idx // width, val_k[keep, joint], tag_k[keep, joint]], axis=1)
        if not people:
            for row in found:
                people.append(np.zeros((17, 4)))
                people[-1][joint] = row
                tags.append([row[3]])
            continue
        groups = list(range(min(len(people), max_num_people)))
        means = np.array([np.mean(tags[g]) for g in groups])
        dist = np.abs(found[:, 3:4] - means[None, :])
        cost = np.round(dist) * 100 - found[:, 2:3]
        rows, cols = linear_sum_assignment(cost)
        taken = {r: c for r, c in zip(rows, cols, strict=True) if dist[r, c] < tag_threshold}
        for r, row in enumerate(found):
            if r in taken:
                g = groups[taken[r]]
                people[g][joint] = row
                tags[g].append(row[3])
            else:
                people.append(np.zeros((17, 4)))
                people[-1][joint] = row
                tags.append([row[3]])
    return people


def postprocess_higherhrnet(outputs: list[np.ndarray], img_size: tuple[int, int], img_w_pad: tuple[int, int],
                            img_h_pad: tuple[int, int], network_postprocess: bool, num_joints: int = 17,
                            tag_per_joint: bool = True, joint_order: list[int] = default_joint_order,
                            detection_threshold: float = 0.3, max_num_people: int = 30, nms_kernel: int = 5,
                            nms_padding: int = 2, ignore_too_much: bool = False, use_detection_val: bool = True,
                            tag_threshold: float = 1.0, adjust: bool = False, refine: bool = False,
                            input_image_size: tuple[int, int] = (288, 384),
                            output_shape: tuple[int, int] = (144, 192)) -> tuple[list[Any], list[Any], list[Any]]:
    """(keypoints, scores, boxes) of the people in one frame's outputs (see the module docstring); sizes are
    (height, width)."""
    if not network_postprocess:
        raise RuntimeError("rollcam's IMX500 sends HigherHRNet's outputs grouped on chip only "
                           "(network_postprocess=True); the raw heatmap heads are not emulated")
    tag_k, ind_k, val_k = (np.asarray(o)[0] for o in outputs[:3])
    people = _group(tag_k, ind_k, val_k, output_shape[1], list(joint_order), detection_threshold, max_num_people,
                    tag_threshold)
    in_h, in_w = input_image_size
    net_h, net_w = in_h - sum(img_h_pad), in_w - sum(img_w_pad)
    keypoints, scores, boxes = [], [], []
    for person in people:
        have = person[:, 2] > 0
        pts = np.zeros((num_joints, 3), np.float32)
        pts[have, 0] = (person[have, 0] * in_w / output_shape[1] - img_w_pad[0]) * img_size[1] / net_w
        pts[have, 1] = (person[have, 1] * in_h / output_shape[0] - img_h_pad[0]) * img_size[0] / net_h
        pts[have, 2] = person[have, 2]
        keypoints.append(list(pts.ravel()))
        scores.append(float(person[:, 2].mean()))
        boxes.append([float(pts[have, 1].min()), float(pts[have, 0].min()), float(pts[have, 1].max()),
                      float(pts[have, 0].max())])
    return keypoints, scores, boxes
