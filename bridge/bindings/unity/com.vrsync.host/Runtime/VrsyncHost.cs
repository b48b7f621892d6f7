// The host of a vrsync session in a Unity scene: owns the Host (libvrsync_host), waits for
// the agents, and runs one cycle per engine frame:
//
//   Update      (frame 2 of cycle f-1)  Collect: every stop or stop_timeout; the commands
//                                      and actions to each IVrsyncBody; EndCycle
//   ...         your scripts' Update/FixedUpdate move the bodies by Time.deltaTime
//   LateUpdate  (frame 1 of cycle f)    per agent: LoanFrame, render its cameras, readbacks
//                                      into the loaned images; sync: wait for them, publish
//                                      (pose, statuses, collisions, vectors), Start
//
// The original AgentScript.Update() spent two engine frames per cycle (frameState) and moved
// bodies by SimulationTimePerFrame by hand; here both halves run in one engine frame, so in
// sync mode Time.captureDeltaTime = simulation_time_per_frame makes physics and animation
// advance by exactly one cycle's simulated time per cycle, whatever the frame rate.
//
// Async mode (sync_mode = false): a cycle every simulation_time_per_frame of real time; the
// readbacks are not waited for (the frame is published in the first LateUpdate after they
// finished), and Collect waits for the library's own tick (up to one period).

using System;
using System.Collections.Generic;
using System.IO;
using UnityEngine;

namespace Vrsync
{
    /// <summary>Where a <see cref="VrsyncHost"/> is.</summary>
    public enum VrsyncHostPhase
    {
        /// <summary>Not started (before Start, or disabled).</summary>
        Idle,
        /// <summary>Session created; waiting for the agents to connect.</summary>
        WaitingForAgents,
        /// <summary>Running cycles.</summary>
        Running,
        /// <summary>An error ended the session (logged; see <see cref="VrsyncHost.Error"/>).</summary>
        Failed,
        /// <summary>The session was closed (disabled or destroyed).</summary>
        Closed,
    }

    /// <summary>
    /// The simulator side of a vrsync session: one per scene. Reads the config
    /// (<see cref="configPath"/>), drives every <see cref="VrsyncAgent"/> of it from
    /// <c>Update</c>/<c>LateUpdate</c>, and closes the session when disabled or destroyed
    /// (the agents then end with exit code 0).
    /// </summary>
    [DefaultExecutionOrder(-1000)]
    [DisallowMultipleComponent]
    [AddComponentMenu("vrsync/Vrsync Host")]
    public sealed class VrsyncHost : MonoBehaviour
    {
        [Tooltip("The session's config file (the one the agents use): absolute, or relative to StreamingAssets")]
        public string configPath = "vrsync.toml";

        [Tooltip("Seconds to wait for the agents before running without the missing ones; negative: the config's connect_timeout")]
        public double agentWaitSeconds = -1;

        [Tooltip("Sync mode: set Time.captureDeltaTime to simulation_time_per_frame (one cycle of simulated time per engine frame)")]
        public bool setCaptureDeltaTime = true;

        [Tooltip("The library's log level (RUST_LOG syntax, e.g. \"info\") into the player log; empty: RUST_LOG or \"warn\"")]
        public string libraryLog = "";

        [Tooltip("The agents to drive; empty: every enabled VrsyncAgent of the scene")]
        public VrsyncAgent[] agents = new VrsyncAgent[0];

        /// <summary>An agent's process died or disconnected (evicted; it may rejoin).</summary>
        public event Action<AgentSummary> AgentEvicted;
        /// <summary>An agent left the session gracefully (its id is free again).</summary>
        public event Action<AgentSummary> AgentLeft;
        /// <summary>The host waited past stop_timeout for a live, busy agent (wait_for_stop = "alive").</summary>
        public event Action<AgentSummary> AgentSlow;
        /// <summary>An agent's stop did not come within stop_timeout (the original's "Normal stop-sync timeout").</summary>
        public event Action<AgentSummary> AgentTimedOut;
        /// <summary>An agent came back after an eviction or a leave.</summary>
        public event Action<AgentSummary> AgentRejoined;
        /// <summary>Connections refused since the last cycle (wrong version, id not served, id in use):
        /// the count, the total so far.</summary>
        public event Action<ulong, ulong> PeersRefused;
        /// <summary>The agents still missing when the wait for them ended; the host runs without them.</summary>
        public event Action<uint[]> AgentsMissing;
        /// <summary>A cycle was collected and every body got its commands.</summary>
        public event Action<CycleResult> CycleCompleted;

        static bool loggingInitialised;

        Host host;
        VrsyncAgent[] bound = new VrsyncAgent[0];
        readonly Dictionary<uint, VrsyncAgent> byId = new Dictionary<uint, VrsyncAgent>();
        SensorFrame[] frames = new SensorFrame[0];
        bool framesLoaned;
        bool started;
        double waitDeadline;
        double nextCycleTime;
        ulong peersRefused;
        float previousCaptureDeltaTime;
        bool captureDeltaTimeSet;

        /// <summary>The session (null before Start and after it closed).</summary>
        public Host Host { get { return host; } }

        /// <summary>Where the host is.</summary>
        public VrsyncHostPhase Phase { get; private set; }

        /// <summary>The exception that ended the session, if one did.</summary>
        public Exception Error { get; private set; }

        /// <summary>The config's sync_mode.</summary>
        public bool SyncMode { get; private set; }

        /// <summary>The config's simulation_time_per_frame, seconds.</summary>
        public double SimulationTimePerFrame { get; private set; }

        /// <summary>The cycle whose frames are being (or were last) loaned and published.</summary>
        public ulong Cycle { get; private set; }

        /// <summary>Cycles collected so far.</summary>
        public long CyclesCompleted { get; private set; }

        /// <summary>The last collected cycle.</summary>
        public CycleResult LastCycle { get; private set; }

        /// <summary>The agents driven, in the config's order.</summary>
        public IList<VrsyncAgent> Agents { get { return Array.AsReadOnly(bound); } }

        /// <summary>The config file's full path.</summary>
        public string ResolvedConfigPath
        {
            get
            {
                if (Path.IsPathRooted(configPath))
                    return configPath;
                return Path.Combine(Application.streamingAssetsPath, configPath);
            }
        }

        void Start()
        {
            if (Phase != VrsyncHostPhase.Idle)
                return;
            try
            {
                Open();
            }
            catch (Exception e)
            {
                Fail(e);
            }
        }

        void Open()
        {
            if (!loggingInitialised)
            {
                Host.InitLogging(string.IsNullOrEmpty(libraryLog) ? null : libraryLog);
                loggingInitialised = true;
            }
            string path = ResolvedConfigPath;
            host = new Host(path);
            HostInfo info = host.Info;
            SyncMode = info.SyncMode != 0;
            SimulationTimePerFrame = info.SimulationTimePerFrame;
            Bind();
            if (SyncMode && setCaptureDeltaTime)
            {
                previousCaptureDeltaTime = Time.captureDeltaTime;
                Time.captureDeltaTime = (float)SimulationTimePerFrame;
                captureDeltaTimeSet = true;
            }
            double wait = agentWaitSeconds < 0 ? info.ConnectTimeout : agentWaitSeconds;
            waitDeadline = Time.realtimeSinceStartupAsDouble + wait;
            Phase = VrsyncHostPhase.WaitingForAgents;
            Debug.Log(string.Format(
                "vrsync: session of {0} ({1} mode, {2} transport, {3} s per cycle, {4} agents); waiting up to {5} s for the agents",
                path, SyncMode ? "sync" : "async", info.Transport, SimulationTimePerFrame, bound.Length, wait));
        }

        /// <summary>One VrsyncAgent per config agent; each binds its body and cameras.</summary>
        void Bind()
        {
            var candidates = new List<VrsyncAgent>();
            if (agents != null && agents.Length > 0)
                candidates.AddRange(agents);
            else
                candidates.AddRange(VrsyncAgent.EnabledAgents);
            byId.Clear();
            foreach (VrsyncAgent a in candidates)
            {
                if (a == null)
                    continue;
                if (byId.ContainsKey(a.agentId))
                    throw new InvalidOperationException(string.Format(
                        "vrsync: two VrsyncAgents with id {0} ({1}, {2})", a.agentId, byId[a.agentId].name, a.name));
                byId.Add(a.agentId, a);
            }
            AgentInfo[] config = host.Agents;
            var ids = new List<uint>();
            foreach (AgentInfo c in config)
                ids.Add(c.Id);
            foreach (VrsyncAgent a in byId.Values)
                if (!ids.Contains(a.agentId))
                    throw new InvalidOperationException(string.Format(
                        "vrsync: VrsyncAgent {0} ({1}) is not an agent of {2} (its agents: {3})",
                        a.agentId, a.name, ResolvedConfigPath, string.Join(", ", ids.ConvertAll(i => i.ToString()).ToArray())));
            bound = new VrsyncAgent[config.Length];
            for (int i = 0; i < config.Length; i++)
            {
                VrsyncAgent a;
                if (!byId.TryGetValue(config[i].Id, out a))
                    throw new InvalidOperationException(string.Format(
                        "vrsync: no VrsyncAgent with agentId {0} in the scene (the config {1} has it)",
                        config[i].Id, ResolvedConfigPath));
                a.Bind(config[i]);
                bound[i] = a;
            }
            frames = new SensorFrame[bound.Length];
        }

        void Update()
        {
            if (host == null)
                return;
            try
            {
                if (Phase == VrsyncHostPhase.WaitingForAgents)
                    WaitForAgents();
                if (Phase != VrsyncHostPhase.Running || !started)
                    return;
                if (SyncMode || Time.realtimeSinceStartupAsDouble >= nextCycleTime)
                    MotorFrame();
            }
            catch (Exception e)
            {
                Fail(e);
            }
        }

        void LateUpdate()
        {
            if (host == null || Phase != VrsyncHostPhase.Running)
                return;
            try
            {
                if (!started && !framesLoaned)
                    BeginSensorFrame();
                if (framesLoaned)
                {
                    if (SyncMode)
                        foreach (VrsyncAgent a in bound)
                            a.WaitForCaptures();
                    else
                        foreach (VrsyncAgent a in bound)
                            if (!a.CapturesDone)
                                return;  // async: publish in a later frame
                    PublishSensorFrame();
                }
            }
            catch (Exception e)
            {
                Fail(e);
            }
        }

        void WaitForAgents()
        {
            uint[] missing;
            if (host.TryWaitForAgents(0, out missing))
            {
                Debug.Log("vrsync: every agent is connected");
                Phase = VrsyncHostPhase.Running;
                UpdateConnected();
                return;
            }
            if (Time.realtimeSinceStartupAsDouble < waitDeadline)
                return;
            Debug.LogWarning(string.Format(
                "vrsync: agents {0} did not connect in time; running without them until they do",
                string.Join(", ", Array.ConvertAll(missing, i => i.ToString()))));
            Phase = VrsyncHostPhase.Running;
            UpdateConnected();
            if (AgentsMissing != null)
                AgentsMissing(missing);
        }

        void UpdateConnected()
        {
            foreach (VrsyncAgent a in bound)
                a.IsConnected = host.IsConnected(a.agentId);
        }

        /// <summary>Frame 1, first half: loan every agent's frame, render, start the readbacks.</summary>
        void BeginSensorFrame()
        {
            Cycle = host.Info.Cycle;
            for (int i = 0; i < bound.Length; i++)
            {
                frames[i] = host.LoanFrame(bound[i].agentId);
                framesLoaned = true;
                bound[i].BeginFrame(frames[i]);
            }
        }

        /// <summary>Frame 1, second half: the images are complete: publish, then one start.</summary>
        void PublishSensorFrame()
        {
            for (int i = 0; i < bound.Length; i++)
                bound[i].FinishFrame(frames[i]);
            framesLoaned = false;
            host.Start();
            started = true;
            if (!SyncMode)
                nextCycleTime = Time.realtimeSinceStartupAsDouble + SimulationTimePerFrame;
        }

        /// <summary>Frame 2: the stops (or stop_timeout), the commands and actions to the bodies.</summary>
        void MotorFrame()
        {
            CycleResult cycle = host.Collect();
            started = false;
            for (int i = 0; i < cycle.AgentCount; i++)
            {
                AgentReport report = host.GetReport(i);
                VrsyncAgent agent;
                if (!byId.TryGetValue(report.AgentId, out agent))
                    continue;
                agent.Deliver(host, report);
                Announce(report.Summary, cycle.Cycle);
            }
            host.EndCycle();
            ulong refused = host.Stats.PeersRefused;
            if (refused > peersRefused)
            {
                Debug.LogWarning(string.Format(
                    "vrsync: {0} connection(s) refused (wrong version, id not served or in use); {1} so far",
                    refused - peersRefused, refused));
                if (PeersRefused != null)
                    PeersRefused(refused - peersRefused, refused);
                peersRefused = refused;
            }
            LastCycle = cycle;
            CyclesCompleted++;
            UpdateConnected();
            if (CycleCompleted != null)
                CycleCompleted(cycle);
        }

        void Announce(AgentSummary s, ulong cycle)
        {
            if (s.Outcome == AgentOutcome.TimedOut)
            {
                Debug.LogWarning(string.Format("vrsync: stop timeout: agent {0}, cycle {1}", s.AgentId, cycle));
                if (AgentTimedOut != null) AgentTimedOut(s);
            }
            if (s.Evicted)
            {
                Debug.LogWarning(string.Format("vrsync: agent {0} evicted in cycle {1} (its process died or disconnected)", s.AgentId, cycle));
                if (AgentEvicted != null) AgentEvicted(s);
            }
            if (s.Left)
            {
                Debug.Log(string.Format("vrsync: agent {0} left the session in cycle {1}", s.AgentId, cycle));
                if (AgentLeft != null) AgentLeft(s);
            }
            if (s.Slow)
            {
                Debug.LogWarning(string.Format("vrsync: agent {0} was slow in cycle {1} (waited past stop_timeout)", s.AgentId, cycle));
                if (AgentSlow != null) AgentSlow(s);
            }
            if (s.Rejoined)
            {
                Debug.Log(string.Format("vrsync: agent {0} rejoined in cycle {1}", s.AgentId, cycle));
                if (AgentRejoined != null) AgentRejoined(s);
            }
        }

        void Fail(Exception e)
        {
            Error = e;
            Debug.LogException(e);
            Close(VrsyncHostPhase.Failed);
        }

        /// <summary>Closes the session: waits for readbacks still writing into loaned frames,
        /// destroys the host (the agents end cleanly), restores Time.captureDeltaTime.</summary>
        void Close(VrsyncHostPhase phase)
        {
            if (framesLoaned)
                foreach (VrsyncAgent a in bound)
                    a.AbandonFrame();
            framesLoaned = false;
            started = false;
            if (host != null)
            {
                host.Dispose();
                host = null;
            }
            if (captureDeltaTimeSet)
            {
                Time.captureDeltaTime = previousCaptureDeltaTime;
                captureDeltaTimeSet = false;
            }
            if (Phase != VrsyncHostPhase.Failed)
                Phase = phase;
        }

        void OnDisable()
        {
            if (host != null)
            {
                Close(VrsyncHostPhase.Closed);
                Debug.Log("vrsync: session closed after " + CyclesCompleted + " cycles");
            }
        }

        void OnDestroy()
        {
            Close(VrsyncHostPhase.Closed);
        }
    }
}
