"""PPO whose env runners sample the next batch while the learner updates on this one.

RLlib's PPO alternates: the env runners sample a batch, then the learner (in
the driver) runs its epochs while the runners wait, then the weights go back.
On a machine with a core per process that leaves each core idle about half the
time.  Here, as soon as batch k arrives, the runners are asked for batch k + 1
(asynchronously) before the learner starts on batch k; the new weights are
queued behind that request (Ray runs an actor's calls in order), so batch k + 1
is sampled with the weights of the previous update: a policy lag of one
iteration, which PPO's importance ratio (taken against the sampling policy's
recorded log-probabilities) and clipping account for.  Batch size, epochs,
minibatches, observations and losses are those of PPO.

Failed runners: a request that does not come back (the runner died) is made up
by a synchronous sample of the missing steps, after RLlib restored the runner.
"""

from __future__ import annotations

from ray.rllib.algorithms.ppo import PPO
from ray.rllib.execution.rollout_ops import synchronous_parallel_sample
from ray.rllib.utils.metrics import (
    ALL_MODULES,
    ENV_RUNNER_RESULTS,
    ENV_RUNNER_SAMPLING_TIMER,
    LEARNER_RESULTS,
    LEARNER_UPDATE_TIMER,
    NUM_ENV_STEPS_SAMPLED,
    NUM_ENV_STEPS_SAMPLED_LIFETIME,
    NUM_MODULE_STEPS_TRAINED_LIFETIME,
    SYNCH_WORKER_WEIGHTS_TIMER,
    TIMERS,
)

TAG = "eosp-overlapped-sample"


def _sample(runner):
    return runner.sample(), runner.get_metrics()


class OverlappedPPO(PPO):
    """PPO with sampling of the next batch overlapped with learning on the current one (see module doc)."""

    def _request_sample(self) -> None:
        self._in_flight = self.env_runner_group.foreach_env_runner_async(_sample, tag=TAG)

    def _collect(self) -> tuple[list, list]:
        group = self.env_runner_group
        episodes, stats = [], []
        got = 0
        while got < self._in_flight:
            ready = group.fetch_ready_async_reqs(tags=TAG, timeout_seconds=self.config.sample_timeout_s)
            for _, (eps, metrics) in ready:
                episodes.extend(eps)
                stats.append(metrics)
            got += len(ready)
            if not ready or group.num_healthy_remote_workers() < self._in_flight:
                break  # a runner failed (or timed out): the rest comes synchronously
        self._in_flight = 0
        steps = sum(int(s.get(NUM_ENV_STEPS_SAMPLED, 0)) for s in stats)
        missing = self.config.total_train_batch_size - steps
        if missing > 0:
            more, more_stats = synchronous_parallel_sample(
                worker_set=group, max_env_steps=missing, sample_timeout_s=self.config.sample_timeout_s,
                _uses_new_env_runners=True, _return_metrics=True)
            episodes.extend(more)
            stats.extend(more_stats)
        return episodes, stats

    def training_step(self) -> None:
        if self.env_runner_group.num_remote_workers() == 0 or self.config.count_steps_by != "env_steps":
            return super().training_step()
        with self.metrics.log_time((TIMERS, ENV_RUNNER_SAMPLING_TIMER)):
            if not getattr(self, "_in_flight", 0):
                self._request_sample()
            episodes, stats = self._collect()
            if not episodes:
                return
            self._request_sample()  # batch k + 1 is sampled while the learner works on batch k
            self.metrics.aggregate(stats, key=ENV_RUNNER_RESULTS)
        with self.metrics.log_time((TIMERS, LEARNER_UPDATE_TIMER)):
            learner_results = self.learner_group.update(
                episodes=episodes,
                timesteps={
                    NUM_ENV_STEPS_SAMPLED_LIFETIME: self.metrics.peek(
                        (ENV_RUNNER_RESULTS, NUM_ENV_STEPS_SAMPLED_LIFETIME)),
                    NUM_MODULE_STEPS_TRAINED_LIFETIME: self.metrics.peek(
                        (LEARNER_RESULTS, ALL_MODULES, NUM_MODULE_STEPS_TRAINED_LIFETIME), default=0),
                },
                num_epochs=self.config.num_epochs,
                minibatch_size=self.config.minibatch_size,
                shuffle_batch_per_epoch=self.config.shuffle_batch_per_epoch,
            )
            self.metrics.aggregate(learner_results, key=LEARNER_RESULTS)
        with self.metrics.log_time((TIMERS, SYNCH_WORKER_WEIGHTS_TIMER)):
            # fire and forget: queued on each runner behind the sample requested above
            self.env_runner_group.sync_weights(
                from_worker_or_learner_group=self.learner_group,
                policies=set(learner_results[0].keys()) - {ALL_MODULES},
                inference_only=True,
            )
