// The Unity-shaped example: how AgentScript.Update() of the original Unity app drives the
// bridge. Plain C#, no UnityEngine: the console host (ConsoleHost.cs) runs it as is, and a
// MonoBehaviour calls Update() from its own Update() (see README.md, "Use from Unity").
//
// The original (vrNew AgentScript.cs, ~lines 1429-1668) alternated two states per Unity
// Update() and agent:
//   FirstFrame:  send MsgStartSync; render the eye cameras into RenderTextures, ReadPixels,
//                EncodeToPNG, send MsgImages; send grid position / eye / head motion.
//   SecondFrame: busy-loop on the main thread over incoming messages until MsgStopSync
//                (5 s timeout: "Normal stop-sync timeout"), ProcessMovement().
// With vrsync the same two states drive all agents at once: one start for everyone, raw
// pixels written straight into shared memory (no PNG), and one deadline for all stops.

using System;
using System.Collections.Generic;

namespace Vrsync.Examples
{
    /// <summary>
    /// What the simulation does for one agent body: the parts of the original AgentScript
    /// that are not networking. In Unity this is the agent's MonoBehaviour.
    /// </summary>
    public interface IAgentBody
    {
        /// <summary>The agent id (the original <c>AgentScript.AgentID</c>).</summary>
        uint AgentId { get; }

        /// <summary>Frame 1: draw every camera into the loaned images
        /// (<c>frame.GetImage(i).Pixels</c>). Unity: render the eye camera into its
        /// RenderTexture, read it back, <c>image.CopyFromBottomUp(readback, stride)</c>.</summary>
        void Render(SensorFrame frame);

        /// <summary>Frame 1: this frame's sensor data (pose, grid, head motion, eye, reward)
        /// and the action statuses and collisions since the previous frame.</summary>
        void WriteSensors(ref Sensors sensors);

        /// <summary>Frame 2: apply one motor command (the original <c>ProcessMsg</c>);
        /// false when it is rejected (unknown kind, NaN, out of range).</summary>
        bool Apply(MotorCommand command);

        /// <summary>Frame 2, last: advance by <paramref name="dtSeconds"/> of simulated time
        /// (the original <c>ProcessMovement()</c>, scaled by SimulationTimePerFrame).</summary>
        void Step(float dtSeconds);
    }

    /// <summary>
    /// Drives a <see cref="Host"/> in lock-step, one state per engine frame like the
    /// original <c>AgentScript.Update()</c>: call <see cref="Update"/> once per frame.
    /// </summary>
    public sealed class SyncDriver
    {
        /// <summary>The original AgentScript's <c>frameState</c>.</summary>
        public enum FrameState
        {
            /// <summary>Sensor frame: publish every agent's frame, then start.</summary>
            FirstFrame,
            /// <summary>Motor frame: wait for the stops, apply the commands, move.</summary>
            SecondFrame,
        }

        readonly Host host;
        readonly IAgentBody[] bodies;
        readonly Dictionary<uint, IAgentBody> byId = new Dictionary<uint, IAgentBody>();
        readonly float dt;
        readonly Action<string> log;

        /// <summary>Which half of the cycle the next <see cref="Update"/> runs.</summary>
        public FrameState State { get; private set; }

        /// <summary>The last collected cycle.</summary>
        public CycleResult LastCycle { get; private set; }

        /// <summary>Cycles completed.</summary>
        public long Cycles { get; private set; }

        /// <summary>Agent-cycles that ended by the stop timeout.</summary>
        public long TimedOutAgentCycles { get; private set; }

        /// <summary>Commands applied / rejected so far, all agents.</summary>
        public long CommandsApplied { get; private set; }
        public long CommandsRejected { get; private set; }

        /// <summary>One body per agent of the config (any order). <paramref name="log"/>
        /// gets the timeout lines (Unity: <c>Debug.LogWarning</c>); may be null.</summary>
        public SyncDriver(Host host, IList<IAgentBody> bodies, Action<string> log)
        {
            this.host = host;
            this.log = log ?? (s => { });
            this.bodies = new IAgentBody[bodies.Count];
            bodies.CopyTo(this.bodies, 0);
            foreach (var b in this.bodies)
                byId.Add(b.AgentId, b);
            foreach (var a in host.Agents)
                if (!byId.ContainsKey(a.Id))
                    throw new ArgumentException("no body for agent " + a.Id + " of the config");
            dt = (float)host.Info.SimulationTimePerFrame;
            State = FrameState.FirstFrame;
        }

        /// <summary>One engine frame: frame 1 or frame 2 of the cycle, alternately.</summary>
        public void Update()
        {
            if (State == FrameState.FirstFrame)
            {
                SensorFrame();
                State = FrameState.SecondFrame;
            }
            else
            {
                MotorFrame();
                State = FrameState.FirstFrame;
            }
        }

        /// <summary>Frame 1: every agent's images and sensors into its loaned frame, then
        /// one start for all (the original sent MsgStartSync per agent).</summary>
        void SensorFrame()
        {
            foreach (var body in bodies)
            {
                SensorFrame frame = host.LoanFrame(body.AgentId);
                body.Render(frame);
                Sensors sensors = Sensors.Create();
                body.WriteSensors(ref sensors);
                frame.Publish(ref sensors);
            }
            host.Start();
        }

        /// <summary>Frame 2: wait for every stop (one deadline for all agents, not N x 5 s),
        /// apply the commands in (agent id, order sent) order, advance the world.</summary>
        void MotorFrame()
        {
            CycleResult cycle = host.Collect();
            LastCycle = cycle;
            for (int i = 0; i < cycle.AgentCount; i++)
            {
                AgentReport report = host.GetReport(i);
                if (report.Outcome == AgentOutcome.TimedOut)
                {
                    TimedOutAgentCycles++;
                    log(string.Format("Normal stop-sync timeout: agent {0}, cycle {1}", report.AgentId, cycle.Cycle));
                }
                IAgentBody body = byId[report.AgentId];
                uint rejected = 0;
                foreach (MotorCommand command in report.Commands)
                {
                    if (body.Apply(command))
                        CommandsApplied++;
                    else
                        rejected++;
                }
                CommandsRejected += rejected;
                host.SetRejected(report.AgentId, rejected);
            }
            host.EndCycle();
            foreach (var body in bodies)
                body.Step(dt);
            Cycles++;
        }
    }
}
