"""A set-aware feature extractor for SB3's `MultiInputPolicy`: masked attention over the pedestrian rows.

In the spirit of SARL (Chen et al. 2019) and CrowdNav++ (Liu et al. 2023): every observed pedestrian row is
embedded together with the robot's own state, optionally with the pooled embedding of its group (rows with the
same `group_ids`), with its predicted future (`predictions`, K samples x 12 steps) and with the calibration of
those predictions (`prediction_error`, 12 steps, and `prediction_error_count`: how wrong this person's predictions
have been so far, `envs.calibration`), and the rows are pooled by attention scores computed against the crowd's
mean. Padding rows (`pedestrian_mask` 0) get no weight, so the weights do not depend on P or on the row order, and
an empty scene gives a zero crowd feature. Wall range rays (`walls`, if observed) are appended to the robot's own
features.

Used through `policy_kwargs=dict(features_extractor_class=CrowdAttentionExtractor,
features_extractor_kwargs=dict(use_groups=True, use_predictions=False, use_calibration=False))`. torch enters
`envs` only here and through stable-baselines3 (the `rl` extra); the rest of the package never imports this module.
"""

from __future__ import annotations

import torch
from gymnasium import spaces
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from torch import nn

# Fixed input scales (m, m/s): positions to about unit size without learned normalisation.
POS_SCALE_M = 5.0
GOAL_SCALE_M = 10.0


def mlp(sizes: list[int], last_act: bool = True) -> nn.Sequential:
    layers: list[nn.Module] = []
    for i in range(len(sizes) - 1):
        layers.append(nn.Linear(sizes[i], sizes[i + 1]))
        if last_act or i < len(sizes) - 2:
            layers.append(nn.ReLU())
    return nn.Sequential(*layers)


class CrowdAttentionExtractor(BaseFeaturesExtractor):
    """Features (robot embedding, attention-pooled crowd embedding) of a CrowdNav observation.

    observation_space: the env's Dict space. embed_dim: width of a pedestrian row's embedding (and of the crowd
    feature). robot_dim: width of the robot embedding. use_groups: add each row's group-pooled embedding and
    its group size. use_predictions: add each row's predicted future (needs `predictions` in the observation).
    use_calibration: add each row's prediction calibration, its 12 quantiles and its count (needs `prediction_error`
    in the observation, `ObservationConfig.prediction_calibration`).
    Output: (B, robot_dim + embed_dim). `traceable`: its forward has no branch on the data (only on the settings), so
    `envs.policies.sb3_actor` may trace it with TorchScript.
    """

    traceable = True

    def __init__(self, observation_space: spaces.Dict, embed_dim: int = 64, robot_dim: int = 32,
                 use_groups: bool = True, use_predictions: bool = False, use_calibration: bool = False) -> None:
        super().__init__(observation_space, features_dim=robot_dim + embed_dim)
        if use_predictions and "predictions" not in observation_space.spaces:
            raise ValueError("use_predictions needs predictions in the observation (ObservationConfig.predictions)")
        if use_calibration and "prediction_error" not in observation_space.spaces:
            raise ValueError("use_calibration needs prediction_error in the observation "
                             "(ObservationConfig.prediction_calibration)")
        self.use_groups, self.use_predictions, self.use_calibration = use_groups, use_predictions, use_calibration
        self.wall_range = float(observation_space["walls"].high[0]) if "walls" in observation_space.spaces else None
        robot_in = observation_space["robot"].shape[0]
        if self.wall_range is not None:  # range rays join the robot's own features
            robot_in += observation_space["walls"].shape[0]
        row_in = 6 + robot_in  # x, y, vx, vy, radius, distance + the robot's own state
        if use_predictions:
            k, t = observation_space["predictions"].shape[:2]
            self.pred_enc = mlp([k * t * 2, 64, 32])
            row_in += 32
        if use_calibration:  # the 12 quantiles (m, to unit size) and the count (over the window)
            self.count_scale = float(observation_space["prediction_error_count"].high[0])
            self.calib_enc = mlp([observation_space["prediction_error"].shape[1] + 1, 32, 16])
            row_in += 16
        self.robot_enc = mlp([robot_in, 64, robot_dim])
        self.row_enc = mlp([row_in, 128, embed_dim])
        if use_groups:
            self.group_enc = mlp([2 * embed_dim + 1, 128, embed_dim])
        self.score = mlp([2 * embed_dim, 64, 1], last_act=False)
        self.value_enc = mlp([embed_dim, embed_dim])

    @staticmethod
    def scaled_robot(robot: torch.Tensor) -> torch.Tensor:
        scale = torch.ones_like(robot[:1])
        scale[:, :3] = GOAL_SCALE_M
        return robot / scale

    def forward(self, obs: dict[str, torch.Tensor]) -> torch.Tensor:
        robot = self.scaled_robot(obs["robot"])
        if self.wall_range is not None:
            robot = torch.cat([robot, obs["walls"] / self.wall_range], dim=-1)
        peds, mask = obs["pedestrians"], obs["pedestrian_mask"] > 0.5  # (B, P, 5), (B, P)
        dist = torch.linalg.norm(peds[..., :2], dim=-1, keepdim=True) / POS_SCALE_M
        rows = [peds[..., :2] / POS_SCALE_M, peds[..., 2:], dist, robot[:, None].expand(-1, peds.shape[1], -1)]
        if self.use_predictions:
            pred = obs["predictions"]  # (B, K, T, P, 2)
            b, k, t, p, _ = pred.shape
            rows.append(self.pred_enc(pred.permute(0, 3, 1, 2, 4).reshape(b, p, k * t * 2) / POS_SCALE_M))
        if self.use_calibration:
            calib = [obs["prediction_error"] / POS_SCALE_M, obs["prediction_error_count"][..., None] / self.count_scale]
            rows.append(self.calib_enc(torch.cat(calib, dim=-1)))  # (B, P, 16)
        h = self.row_enc(torch.cat(rows, dim=-1))  # (B, P, E)
        m = mask.float()
        if self.use_groups:
            gid = obs["group_ids"]
            same = (gid[:, :, None] == gid[:, None, :]).float() * m[:, :, None] * m[:, None, :]  # (B, P, P)
            size = same.sum(-1, keepdim=True)
            pooled = same @ h / size.clamp(min=1.0)
            h = self.group_enc(torch.cat([h, pooled, size / peds.shape[1]], dim=-1))
        mean = (h * m[..., None]).sum(1) / m.sum(1, keepdim=True).clamp(min=1.0)  # (B, E)
        logits = self.score(torch.cat([h, mean[:, None].expand_as(h)], dim=-1)).squeeze(-1)
        w = torch.softmax(logits.masked_fill(~mask, -1e9), dim=1) * m
        w = w / w.sum(1, keepdim=True).clamp(min=1e-8)
        crowd = (w[..., None] * self.value_enc(h)).sum(1)
        return torch.cat([self.robot_enc(robot), crowd], dim=-1)


EXTRACTORS: dict[str, type[BaseFeaturesExtractor]] = {"crowd-attention": CrowdAttentionExtractor}
