// One agent of the config on a GameObject: its pose comes from this Transform, its cameras
// are the VrsyncCameras under it (by name), its commands and channel actions go to the
// IVrsyncBody, and the statuses and collisions the body reports go back with the next frame.

using System;
using System.Collections.Generic;
using UnityEngine;

namespace Vrsync
{
    /// <summary>
    /// Agent <see cref="agentId"/> of the config (the original <c>AgentScript.AgentID</c>).
    /// Put it on the body's GameObject, a <see cref="VrsyncCamera"/> per config camera on
    /// Cameras under it, and an <see cref="IVrsyncBody"/> on it (or name one in
    /// <see cref="body"/>). The <see cref="VrsyncHost"/> drives it.
    /// </summary>
    [DisallowMultipleComponent]
    [AddComponentMenu("vrsync/Vrsync Agent")]
    public sealed class VrsyncAgent : MonoBehaviour
    {
        [Tooltip("The agent's id in the config ([[agent]] id)")]
        public uint agentId;

        [Tooltip("The behaviour implementing IVrsyncBody; empty: the first one on this GameObject")]
        public MonoBehaviour body;

        static readonly List<VrsyncAgent> enabledAgents = new List<VrsyncAgent>();

        Sensors events = Sensors.Create();
        VrsyncCamera[] cameras = new VrsyncCamera[0];
        IVrsyncBody bodyImpl;
        bool eventsOverflowWarned;

        /// <summary>The config's view of this agent (cameras, vectors, actions); set when the host starts.</summary>
        public AgentInfo Info { get; private set; }

        /// <summary>The cameras in the config's order.</summary>
        public IList<VrsyncCamera> Cameras { get { return Array.AsReadOnly(cameras); } }

        /// <summary>The body commands go to.</summary>
        public IVrsyncBody Body { get { return bodyImpl; } }

        /// <summary>Commands applied / rejected so far.</summary>
        public long CommandsApplied { get; private set; }
        public long CommandsRejected { get; private set; }

        /// <summary>This agent's part of the last collected cycle.</summary>
        public AgentSummary LastSummary { get; private set; }

        /// <summary>Whether the agent's process is connected now.</summary>
        public bool IsConnected { get; internal set; }

        internal static List<VrsyncAgent> EnabledAgents { get { return enabledAgents; } }

        void OnEnable()
        {
            if (!enabledAgents.Contains(this))
                enabledAgents.Add(this);
        }

        void OnDisable()
        {
            enabledAgents.Remove(this);
        }

        /// <summary>
        /// Reports the state of action <paramref name="actionId"/> (the
        /// <see cref="MotorCommand.ActionId"/> of the command that started it); it goes out
        /// with the next frame. False when this frame already holds
        /// <see cref="Sensors.MaxStatuses"/> (the rest are dropped and counted).
        /// </summary>
        public bool ReportStatus(uint actionId, ActionState state)
        {
            return Check(events.AddStatus(actionId, state));
        }

        /// <summary>Reports a collision during action <paramref name="actionId"/> with
        /// <paramref name="colliderId"/>; it goes out with the next frame.</summary>
        public bool ReportCollision(uint actionId, uint colliderId)
        {
            return Check(events.AddCollision(actionId, colliderId));
        }

        bool Check(bool added)
        {
            if (!added && !eventsOverflowWarned)
            {
                Debug.LogWarning("vrsync: agent " + agentId + " reported more statuses or collisions than one frame holds; the rest are dropped");
                eventsOverflowWarned = true;
            }
            return added;
        }

        /// <summary>Finds the body and the cameras for <paramref name="info"/> and sets the
        /// cameras up (the host calls it when it starts).</summary>
        internal void Bind(AgentInfo info)
        {
            Info = info;
            bodyImpl = body as IVrsyncBody;
            if (body != null && bodyImpl == null)
                throw new InvalidOperationException(string.Format(
                    "VrsyncAgent {0}: {1} does not implement IVrsyncBody", agentId, body.GetType().Name));
            if (bodyImpl == null)
                bodyImpl = GetComponent<IVrsyncBody>();
            if (bodyImpl == null)
                throw new InvalidOperationException(string.Format(
                    "VrsyncAgent {0} ({1}): no IVrsyncBody on its GameObject; add your body script or set 'body'",
                    agentId, name));
            VrsyncCamera[] found = GetComponentsInChildren<VrsyncCamera>(true);
            cameras = new VrsyncCamera[info.Cameras.Length];
            for (int i = 0; i < info.Cameras.Length; i++)
            {
                string wanted = info.Cameras[i].Name;
                foreach (VrsyncCamera c in found)
                {
                    if (c.cameraName != wanted)
                        continue;
                    if (cameras[i] != null)
                        throw new InvalidOperationException(string.Format(
                            "VrsyncAgent {0}: two VrsyncCameras named \"{1}\"", agentId, wanted));
                    cameras[i] = c;
                }
                if (cameras[i] == null)
                    throw new InvalidOperationException(string.Format(
                        "VrsyncAgent {0} ({1}): no VrsyncCamera named \"{2}\" under it (the config's cameras: {3})",
                        agentId, name, wanted, CameraNames(info)));
            }
            foreach (VrsyncCamera c in found)
                if (Array.IndexOf(cameras, c) < 0)
                    throw new InvalidOperationException(string.Format(
                        "VrsyncAgent {0}: VrsyncCamera \"{1}\" is not a camera of this agent in the config (its cameras: {2})",
                        agentId, c.cameraName, CameraNames(info)));
            for (int i = 0; i < cameras.Length; i++)
                cameras[i].Bind(info.Cameras[i]);
        }

        static string CameraNames(AgentInfo info)
        {
            var names = new string[info.Cameras.Length];
            for (int i = 0; i < names.Length; i++)
                names[i] = info.Cameras[i].Name;
            return string.Join(", ", names);
        }

        /// <summary>Frame 1: renders every camera and starts its readback into the frame.</summary>
        internal void BeginFrame(SensorFrame frame)
        {
            for (int i = 0; i < cameras.Length; i++)
                cameras[i].BeginCapture(frame.GetImage(i));
        }

        /// <summary>Whether every camera's readback has finished.</summary>
        internal bool CapturesDone
        {
            get
            {
                foreach (VrsyncCamera c in cameras)
                    if (!c.CaptureDone)
                        return false;
                return true;
            }
        }

        /// <summary>Blocks until every camera's readback is done.</summary>
        internal void WaitForCaptures()
        {
            foreach (VrsyncCamera c in cameras)
                c.WaitForCapture();
        }

        /// <summary>Frame 1, last: the images complete, the pose, the events and the body's
        /// sensors into the frame, then publishes it.</summary>
        internal void FinishFrame(SensorFrame frame)
        {
            foreach (VrsyncCamera c in cameras)
                c.EndCapture();
            Sensors sensors = Sensors.Create();
            Transform t = transform;
            Vector3 p = t.position;
            Quaternion q = t.rotation;
            sensors.Pose.Position = new Vec3(p.x, p.y, p.z);
            sensors.Pose.Rotation = new Quat(q.x, q.y, q.z, q.w);
            for (int i = 0; i < events.StatusCount; i++)
            {
                ActionStatus s = events.GetStatus(i);
                sensors.AddStatus(s.ActionId, s.State);
            }
            for (int i = 0; i < events.CollisionCount; i++)
            {
                Collision c = events.GetCollision(i);
                sensors.AddCollision(c.ActionId, c.ColliderId);
            }
            try
            {
                bodyImpl.WriteSensors(this, frame, ref sensors);
            }
            catch (Exception e)
            {
                // A bug in the body script costs its extra sensors, not the session.
                Debug.LogException(e);
            }
            frame.Publish(ref sensors);
            events.ClearEvents();
            eventsOverflowWarned = false;
        }

        /// <summary>Shutdown: waits for readbacks still writing into a loaned frame.</summary>
        internal void AbandonFrame()
        {
            foreach (VrsyncCamera c in cameras)
                c.AbandonCapture();
        }

        /// <summary>Frame 2: the agent's commands, then its actions, to the body; the
        /// rejected count back to the host.</summary>
        internal void Deliver(Host host, AgentReport report)
        {
            LastSummary = report.Summary;
            uint rejected = 0;
            foreach (MotorCommand command in report.Commands)
            {
                bool applied;
                try
                {
                    applied = bodyImpl.Apply(this, command);
                }
                catch (Exception e)
                {
                    // Logged like any script exception; the command counts as rejected.
                    Debug.LogException(e);
                    applied = false;
                }
                if (applied)
                    CommandsApplied++;
                else
                    rejected++;
            }
            CommandsRejected += rejected;
            host.SetRejected(report.AgentId, rejected);
            if (report.Outcome == AgentOutcome.NotAwaited)
                return;
            try
            {
                bodyImpl.ApplyActions(this, report);
            }
            catch (Exception e)
            {
                Debug.LogException(e);
            }
        }
    }
}
