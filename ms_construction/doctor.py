"""Says whether physics and rendering work here and, if not, what is missing and how to fix it.

    python -m ms_construction.doctor
"""

from __future__ import annotations

import sys
import traceback

FIX_VULKAN = """SAPIEN needs a Vulkan device, even for physics only. On a CPU-only Debian bookworm machine that
is Mesa's lavapipe, version 23 or newer (bookworm's own 22.3 is too old). Install it from
bookworm-backports, reusing the mirror of your Debian sources file (as root):
    bash scripts/setup.sh          # does exactly this when run as root
or see the commands it prints when run as a normal user."""


def _check(name: str, fn) -> bool:
    try:
        detail = fn()
        print(f"[ok]   {name}: {detail}")
        return True
    except Exception as e:  # the doctor reports, it does not crash
        print(f"[FAIL] {name}: {type(e).__name__}: {e}")
        if "-v" in sys.argv:
            traceback.print_exc()
        return False


def check_vulkan() -> str:
    import sapien

    summary = sapien.render.get_device_summary()
    if "Supported: 1" not in summary:
        raise RuntimeError(f"no Vulkan device SAPIEN supports; it found: {summary.strip() or 'none'}")
    return summary.splitlines()[0].strip()


def check_assets() -> str:
    from ms_construction.assets import load_manifest

    m = load_manifest()
    return f"{len(m['files'])} files match the manifest"


def check_physics() -> str:
    import gymnasium as gym
    import torch

    import ms_construction  # noqa: F401

    env = gym.make("ConstructionPickPlace-v1", obs_mode="state", render_mode=None)
    env.reset(seed=0)
    for _ in range(5):
        env.step(env.action_space.sample())
    qpos = env.unwrapped.agent.robot.get_qpos()
    env.close()
    if not torch.isfinite(qpos).all():
        raise RuntimeError("simulation produced non-finite joint positions")
    return "physx_cpu steps the general task"


def check_render() -> str:
    import gymnasium as gym

    import ms_construction  # noqa: F401

    env = gym.make("Flooring-v1", obs_mode="rgb", render_mode="rgb_array")
    obs, _ = env.reset(seed=0)
    img = env.render()
    env.close()
    std = float(img.float().std())
    if std < 5:
        raise RuntimeError(f"the rendered image is flat (pixel std {std:.1f})")
    cam = obs["sensor_data"]["base_camera"]["rgb"]
    return f"human render {tuple(img.shape[1:3])} (pixel std {std:.0f}), sensor camera {tuple(cam.shape[1:3])}"


def main() -> int:
    ok = _check("vulkan", check_vulkan)
    if not ok:
        print(FIX_VULKAN)
        return 1
    ok = _check("assets", check_assets)
    if not ok:
        from ms_construction.assets import REBUILD_COMMAND

        print(f"Rebuild the assets with: {REBUILD_COMMAND}")
        return 1
    ok = _check("physics", check_physics) and _check("rendering", check_render)
    print("all good" if ok else "see the failures above; rerun with -v for tracebacks")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
