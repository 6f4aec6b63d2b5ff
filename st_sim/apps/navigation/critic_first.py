"""PPO that fits its critic before its actor moves: the first updates train only the value function.

A policy cloned from a teacher acts well but its critic knows little of the training reward (cloned to the teacher's
returns, on the teacher's states). PPO's first updates would then push the actor along the advantages of a wrong
critic and undo the clone. ``CriticFirstPPO`` spends its first ``critic_rollouts`` updates on the critic alone (its
layers and value head, on the rollouts the unchanged actor collects; the shared features extractor held), then runs
as stable-baselines3's PPO.

    model = CriticFirstPPO("MlpPolicy", env, critic_rollouts=8, target_kl=0.02)
"""

from __future__ import annotations

from typing import Any

import torch
from stable_baselines3 import PPO
from torch.nn import functional


class CriticFirstPPO(PPO):
    """stable-baselines3 PPO whose first ``critic_rollouts`` updates fit only the critic (see the module docstring).

    Args:
        critic_rollouts: updates (one per rollout) that train only the value function; then PPO as usual.
        args, kwargs: as ``stable_baselines3.PPO``.
    """

    def __init__(self, *args: Any, critic_rollouts: int = 0, **kwargs: Any):
        super().__init__(*args, **kwargs)
        self.critic_rollouts = int(critic_rollouts)
        self.critic_updates = 0  # critic-only updates done (saved with the model, so a resumed run goes on counting)

    def train(self) -> None:
        if self.critic_updates >= self.critic_rollouts:
            super().train()
            return
        self.policy.set_training_mode(True)
        critic = [*self.policy.mlp_extractor.value_net.parameters(), *self.policy.value_net.parameters()]
        if getattr(self, "_critic_optimizer", None) is None:
            self._critic_optimizer = torch.optim.Adam(critic, lr=self.lr_schedule(self._current_progress_remaining))
        losses = []
        for _ in range(self.n_epochs):
            for batch in self.rollout_buffer.get(self.batch_size):
                with torch.no_grad():
                    features = self.policy.extract_features(batch.observations, self.policy.vf_features_extractor)
                values = self.policy.value_net(self.policy.mlp_extractor.forward_critic(features)).flatten()
                loss = functional.mse_loss(batch.returns, values)
                self._critic_optimizer.zero_grad()
                loss.backward()
                torch.nn.utils.clip_grad_norm_(critic, self.max_grad_norm)
                self._critic_optimizer.step()
                losses.append(loss.item())
        self.critic_updates += 1
        self.logger.record("train/value_loss", sum(losses) / len(losses))
        self.logger.record("train/critic_only", 1)

    def _excluded_save_params(self) -> list[str]:
        return [*super()._excluded_save_params(), "_critic_optimizer"]
