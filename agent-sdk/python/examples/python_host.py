import hashlib
import os
import sys

os.environ.setdefault("MUJOCO_GL", "egl")  # render headless (set before importing mujoco)
import mujoco  # noqa: E402
import vrsync  # noqa: E402

config, frames = sys.argv[1], int(sys.argv[2])
host = vrsync.Host(config)  # serves the config's agents over their transports
ids = host.agent_ids
# The scene: one ball per agent on a plane, driven by two motors, with a camera on it.
balls = "".join(
    f"<body name='ball{k}' pos='{k} 0 .1'><joint name='x{k}' type='slide' axis='1 0 0'/>"
    f"<joint name='y{k}' type='slide' axis='0 1 0'/><geom type='sphere' size='.1'/>"
    f"<camera name='eye{k}' pos='0 -.6 .3' xyaxes='1 0 0 0 .5 1'/></body>"
    for k in range(len(ids))
)
motors = "".join(f"<motor joint='{j}{k}' ctrlrange='-1 1'/>" for k in range(len(ids)) for j in "xy")
model = mujoco.MjModel.from_xml_string(
    f"<mujoco><worldbody><light pos='0 0 3'/><geom type='plane' size='9 9 .1'/>{balls}"
    f"</worldbody><actuator>{motors}</actuator></mujoco>"
)
data = mujoco.MjData(model)
model.vis.quality.shadowsize = 0  # no shadow map: ~15x faster on a CPU renderer
renderer = mujoco.Renderer(model, 84, 84)  # the size of the config's cameras
steps = round(host.simulation_time_per_frame / model.opt.timestep)
trajectory = hashlib.sha256()
host.wait_for_agents(30)
for _ in range(frames):
    for k, agent_id in enumerate(ids):  # frame 1: every agent's sensor frame
        frame = host.loan(agent_id)
        renderer.update_scene(data, camera=f"eye{k}")
        renderer.render(out=frame.image("eye"))  # the pixels go straight into the frame
        frame.vector("state")[:] = [*data.qpos[2 * k : 2 * k + 2], *data.qvel[2 * k : 2 * k + 2]]
        host.publish(frame)  # the views above were temporaries: none is alive any more
    host.start()
    report = host.collect()  # frame 2: every agent's stop (or the stop timeout)
    for k, agent_id in enumerate(ids):
        force = report.agent(agent_id).actions["force"]  # float32 array, None if none sent
        if force is not None:
            data.ctrl[2 * k : 2 * k + 2] = force
    mujoco.mj_step(model, data, nstep=steps)  # exactly simulation_time_per_frame
    trajectory.update(data.qpos.tobytes())
print("stop_timeouts", host.stats()["stop_timeouts"], "hash", trajectory.hexdigest()[:16])
host.close()
