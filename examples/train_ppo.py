"""Train PPO on a visualenv env with nothing but `visualenv.make` and Stable-Baselines3.

For users who bring their own loop. `visualenv train` does the same with
evaluation, plots and a run folder.

    python examples/train_ppo.py --env VisualCartPole-v0 --steps 200000 --envs 2
"""

from __future__ import annotations

import argparse

from stable_baselines3 import PPO
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import SubprocVecEnv, VecFrameStack

import visualenv


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--env", default="VisualCartPole-v0", help="spec path, build folder or id")
    parser.add_argument("--steps", type=int, default=200_000)
    parser.add_argument("--envs", type=int, default=2, help="parallel envs, one Blender process each")
    parser.add_argument("--out", default="ppo_visualenv.zip")
    args = parser.parse_args()

    # one Blender per process: SubprocVecEnv builds each env in its own worker
    venv = make_vec_env(
        visualenv.make,
        n_envs=args.envs,
        env_kwargs={"target": args.env, "threads": 1},
        vec_env_cls=SubprocVecEnv if args.envs > 1 else None,
    )
    venv = VecFrameStack(venv, n_stack=4)  # 4 grayscale frames on the channel axis, as in the paper
    model = PPO("CnnPolicy", venv, verbose=1)
    model.learn(total_timesteps=args.steps, progress_bar=True)
    model.save(args.out)
    venv.close()


if __name__ == "__main__":
    main()
