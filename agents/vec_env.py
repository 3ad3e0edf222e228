"""Several training envs per worker process: `GroupedSubprocVecEnv`, an SB3 VecEnv.

SB3's SubprocVecEnv runs one env per process. Each step then costs the learner a pipe write and read per env, and
on two cores every write wakes a worker that preempts the learner: measured, 4 and 8 envs in as many processes
trained no faster than 2. Here `n_workers` processes each step a contiguous group of the envs in turn and answer in
one message. Each env steps exactly as under SubprocVecEnv (the same auto-reset, `terminal_observation` and
`TimeLimit.truncated`), so the same env functions and seeds give the same transitions.
"""

from __future__ import annotations

import multiprocessing as mp
import os
from collections.abc import Callable, Sequence
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np
from stable_baselines3.common.env_util import is_wrapped
from stable_baselines3.common.vec_env.base_vec_env import CloudpickleWrapper, VecEnv, VecEnvIndices
from stable_baselines3.common.vec_env.patch_gym import _patch_env
from stable_baselines3.common.vec_env.subproc_vec_env import _stack_obs

from trade.validation import require


def _step(env: gym.Env, action: Any) -> tuple[Any, SupportsFloat, bool, dict, dict]:
    """One env's step as SubprocVecEnv's worker does it: (obs, reward, done, info, reset info)."""
    observation, reward, terminated, truncated, info = env.step(action)
    done = terminated or truncated
    info["TimeLimit.truncated"] = truncated and not terminated
    reset_info: dict = {}
    if done:
        info["terminal_observation"] = observation
        observation, reset_info = env.reset()
    return observation, reward, done, info, reset_info


def _worker(remote: Any, parent_remote: Any, env_fns: CloudpickleWrapper) -> None:
    """Serve one group of envs: every command names its envs by their index within the group."""
    parent_remote.close()
    if hasattr(os, "SCHED_BATCH"):  # Linux: a woken worker does not preempt the learner as it sends the next group
        os.sched_setscheduler(0, os.SCHED_BATCH, os.sched_param(0))
    envs = [_patch_env(fn()) for fn in env_fns.var]
    while True:
        try:
            cmd, data = remote.recv()
        except (EOFError, KeyboardInterrupt):
            break
        if cmd == "step":
            remote.send([_step(env, action) for env, action in zip(envs, data, strict=True)])
        elif cmd == "reset":
            remote.send([envs[i].reset(seed=seed, **({"options": options} if options else {}))
                         for i, seed, options in data])
        elif cmd == "close":
            for env in envs:
                env.close()
            remote.close()
            break
        elif cmd == "call":  # (local indices, kind, args): one answer per env
            indices, kind, args = data
            remote.send([_call(envs[i], kind, args) for i in indices])
        else:
            raise NotImplementedError(f"`{cmd}` is not implemented in the worker")


def _call(env: gym.Env, kind: str, args: tuple) -> Any:
    """What the VecEnv's `kind` of call asks of one env."""
    if kind == "method":
        name, method_args, method_kwargs = args
        return env.get_wrapper_attr(name)(*method_args, **method_kwargs)
    if kind == "get_attr":
        return env.get_wrapper_attr(args[0])
    if kind == "has_attr":
        try:
            env.get_wrapper_attr(args[0])
        except AttributeError:
            return False
        return True
    if kind == "set_attr":
        return setattr(env, args[0], args[1])
    if kind == "is_wrapped":
        return is_wrapped(env, args[0])
    if kind == "render":
        return env.render()
    if kind == "spaces":
        return env.observation_space, env.action_space
    raise NotImplementedError(f"`{kind}` is not implemented in the worker")


def worker_groups(n_envs: int, n_workers: int) -> list[range]:
    """The envs of each worker: contiguous, sizes differing by at most one."""
    bounds = np.linspace(0, n_envs, n_workers + 1).round().astype(int)
    return [range(int(a), int(b)) for a, b in zip(bounds[:-1], bounds[1:], strict=True)]


class GroupedSubprocVecEnv(VecEnv):
    """`len(env_fns)` envs in `n_workers` processes (`worker_groups`); the VecEnv API of SubprocVecEnv."""

    def __init__(self, env_fns: Sequence[Callable[[], gym.Env]], n_workers: int, start_method: str = "spawn") -> None:
        require(1 <= n_workers <= len(env_fns), "n_workers", n_workers, f"in [1, {len(env_fns)}] (the envs)")
        self.groups = worker_groups(len(env_fns), n_workers)
        self._where = [(w, i) for w, group in enumerate(self.groups) for i in range(len(group))]
        ctx = mp.get_context(start_method)
        pipes = [ctx.Pipe() for _ in self.groups]
        self.remotes = [parent for parent, _ in pipes]
        self.processes = []
        for (remote, work_remote), group in zip(pipes, self.groups, strict=True):
            fns = CloudpickleWrapper([env_fns[i] for i in group])
            process = ctx.Process(target=_worker, args=(work_remote, remote, fns), daemon=True)  # type: ignore[attr-defined]
            process.start()
            self.processes.append(process)
            work_remote.close()
        self.waiting, self.closed = False, False
        observation_space, action_space = self._call("spaces", [0])[0]
        super().__init__(len(env_fns), observation_space, action_space)

    def step_async(self, actions: np.ndarray) -> None:
        for remote, group in zip(self.remotes, self.groups, strict=True):
            remote.send(("step", [actions[i] for i in group]))
        self.waiting = True

    def step_wait(self):
        results = [r for remote in self.remotes for r in remote.recv()]
        self.waiting = False
        obs, rewards, dones, infos, reset_infos = zip(*results, strict=True)
        self.reset_infos = list(reset_infos)
        return _stack_obs(obs, self.observation_space), np.stack(rewards), np.stack(dones), infos

    def reset(self):
        for remote, group in zip(self.remotes, self.groups, strict=True):
            remote.send(("reset", [(i - group.start, self._seeds[i], self._options[i]) for i in group]))
        results = [r for remote in self.remotes for r in remote.recv()]
        obs, reset_infos = zip(*results, strict=True)
        self.reset_infos = list(reset_infos)
        self._reset_seeds()  # seeds and options are used once, as SB3's VecEnvs do
        self._reset_options()
        return _stack_obs(obs, self.observation_space)

    def close(self) -> None:
        if self.closed:
            return
        if self.waiting:
            for remote in self.remotes:
                remote.recv()
        for remote in self.remotes:
            remote.send(("close", None))
        for process in self.processes:
            process.join()
        for remote in self.remotes:
            remote.close()
        self.closed = True

    def _call(self, kind: str, indices: VecEnvIndices, *args: Any) -> list[Any]:
        """A `kind` of call (see `_call` above) on the envs `indices` (None: all), answers in their order."""
        wanted = list(self._get_indices(indices))
        by_worker: dict[int, list[int]] = {}
        for i in wanted:
            by_worker.setdefault(self._where[i][0], []).append(self._where[i][1])
        for w, local in by_worker.items():
            self.remotes[w].send(("call", (local, kind, args)))
        answers = {w: iter(self.remotes[w].recv()) for w in by_worker}
        return [next(answers[self._where[i][0]]) for i in wanted]

    def get_images(self) -> Sequence[np.ndarray | None]:
        return self._call("render", None)

    def has_attr(self, attr_name: str) -> bool:
        return all(self._call("has_attr", None, attr_name))

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        return self._call("get_attr", indices, attr_name)

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        self._call("set_attr", indices, attr_name, value)

    def env_method(self, method_name: str, *method_args, indices: VecEnvIndices = None, **method_kwargs) -> list[Any]:
        return self._call("method", indices, method_name, method_args, method_kwargs)

    def env_is_wrapped(self, wrapper_class: type[gym.Wrapper], indices: VecEnvIndices = None) -> list[bool]:
        return self._call("is_wrapped", indices, wrapper_class)
