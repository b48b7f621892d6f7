// vrsync C# binding: the host API (Vrsync.Host) over libvrsync_host.
//
// One cycle, as the original Unity app's AgentScript.Update() ran it in two engine frames:
//   frame 1: for each agent  var f = host.LoanFrame(id);  write f.GetImage(i).Pixels
//            (and f.Vector("joints"): Channels.cs);  f.Publish(ref sensors);
//            then  host.Start();
//   frame 2: var c = host.Collect();   (blocks until every stop, or stop_timeout)
//            for i < c.AgentCount: var r = host.GetReport(i); apply r.Commands
//            (and r.Action("torque"));
//            host.EndCycle();
// A Host belongs to the thread that created it (Unity: the main thread).

using System;
using System.Runtime.InteropServices;

namespace Vrsync
{
    /// <summary>A call into libvrsync_host failed; <see cref="Exception.Message"/> is the
    /// library's own message.</summary>
    public class VrsyncException : Exception
    {
        /// <summary>The C status code.</summary>
        public Status Status { get; private set; }

        /// <summary>The C function that failed.</summary>
        public string Call { get; private set; }

        public VrsyncException(Status status, string call, string message)
            : base(string.Format("{0}{1} ({2})",
                message.StartsWith(call + ":") ? "" : call + ": ", message, Native.StatusName(status)))
        {
            Status = status;
            Call = call;
        }
    }

    /// <summary>Some agents did not connect within the timeout.</summary>
    public class AgentsMissingException : VrsyncException
    {
        /// <summary>Ids of the agents still missing.</summary>
        public uint[] Missing { get; private set; }

        public AgentsMissingException(uint[] missing, string message)
            : base(Status.Timeout, "vrs_host_wait_for_agents", message)
        {
            Missing = missing;
        }
    }

    /// <summary>The native host handle. Releasing it destroys the host; from a finalizer
    /// thread the library defers that to the owning thread's next call.</summary>
    public sealed class HostHandle : SafeHandle
    {
        public HostHandle() : base(IntPtr.Zero, true) { }

        public override bool IsInvalid
        {
            get { return handle == IntPtr.Zero; }
        }

        protected override bool ReleaseHandle()
        {
            return Native.vrs_host_destroy(handle) >= Status.Ok;
        }
    }

    /// <summary>
    /// One writable image of a loaned frame. On the shared-memory transport
    /// <see cref="Pixels"/> is the memory the agent reads: write every byte (it holds an
    /// older frame), rows top to bottom, <see cref="Stride"/> bytes apart. Valid until the
    /// frame is published or discarded.
    /// </summary>
    public readonly unsafe struct Image
    {
        readonly byte* data;

        /// <summary>Bytes at <see cref="Data"/> (<c>Stride * Height</c>).</summary>
        public readonly int Length;
        public readonly int Width;
        public readonly int Height;
        /// <summary>Bytes per row (no padding).</summary>
        public readonly int Stride;
        public readonly PixelFormat Format;
        /// <summary>Index in the agent's camera list (<see cref="Host.GetCamera"/>).</summary>
        public readonly int Camera;

        /// <summary>Bytes of one pixel of <see cref="Format"/>: 3 (Rgb8), 4 (Rgba8),
        /// 1 (Gray8), 4 (Depth32f).</summary>
        public int BytesPerPixel
        {
            get
            {
                switch (Format)
                {
                    case PixelFormat.Rgb8: return 3;
                    case PixelFormat.Rgba8: return 4;
                    case PixelFormat.Gray8: return 1;
                    case PixelFormat.Depth32f: return 4;
                    default: throw new InvalidOperationException("unknown pixel format " + Format);
                }
            }
        }

        internal Image(NativeStructs.Image n)
        {
            data = n.Data;
            Length = checked((int)n.Length);
            Width = (int)n.Width;
            Height = (int)n.Height;
            Stride = checked((int)n.Stride);
            Format = n.Format;
            Camera = (int)n.Camera;
        }

        /// <summary>The first byte of the top row (for native plugins and <c>Buffer.MemoryCopy</c>).</summary>
        public IntPtr Data
        {
            get { return (IntPtr)data; }
        }

        /// <summary>The pixels, writable, straight into the loaned frame.</summary>
        public Span<byte> Pixels
        {
            get { return new Span<byte>(data, Length); }
        }

        /// <summary>Row <paramref name="y"/> (0 = top).</summary>
        public Span<byte> Row(int y)
        {
            if ((uint)y >= (uint)Height)
                throw new ArgumentOutOfRangeException("y");
            return new Span<byte>(data + (long)y * Stride, Stride);
        }

        /// <summary>
        /// Copies an image whose rows run bottom to top — what Unity's
        /// <c>Texture2D.GetRawTextureData</c> and <c>AsyncGPUReadback</c> return — flipping it
        /// into this top-down image. <paramref name="sourceStride"/> bytes per source row
        /// (at least <see cref="Stride"/>); same pixel format. The one copy on the way from
        /// the GPU to the agent.
        /// </summary>
        public void CopyFromBottomUp(ReadOnlySpan<byte> source, int sourceStride)
        {
            if (sourceStride < Stride || source.Length < (long)sourceStride * (Height - 1) + Stride)
                throw new ArgumentException(string.Format(
                    "source of {0} bytes with stride {1} does not hold {2}x{3} {4} ({5} bytes per row)",
                    source.Length, sourceStride, Width, Height, Format, Stride));
            for (int y = 0; y < Height; y++)
                source.Slice((Height - 1 - y) * sourceStride, Stride).CopyTo(Row(y));
        }

        /// <summary>Copies a top-down image of the same size and format.</summary>
        public void CopyFrom(ReadOnlySpan<byte> source)
        {
            if (source.Length != Length)
                throw new ArgumentException(string.Format(
                    "source has {0} bytes, the image {1}", source.Length, Length));
            source.CopyTo(Pixels);
        }
    }

    /// <summary>
    /// Agent <see cref="AgentId"/>'s sensor frame of cycle <see cref="Cycle"/>, loaned by
    /// <see cref="Host.LoanFrame"/>: write the images, then <see cref="Publish"/> it (or
    /// <see cref="Discard"/> it).
    /// </summary>
    public readonly partial struct SensorFrame
    {
        /// <summary>Most images (cameras) per agent.</summary>
        public const int MaxImages = 4;

        readonly Host host;
        public readonly uint AgentId;
        public readonly ulong Cycle;
        /// <summary>Simulated time of the cycle in nanoseconds (as the C API gives it);
        /// <see cref="SimTime"/> in seconds.</summary>
        public readonly ulong SimTimeNs;
        public readonly int ImageCount;

        /// <summary>Simulated time of the cycle, seconds.</summary>
        public double SimTime
        {
            get { return SimTimeNs / 1e9; }
        }

        internal SensorFrame(Host host, NativeStructs.Frame f)
        {
            this.host = host;
            AgentId = f.AgentId;
            Cycle = f.Cycle;
            SimTimeNs = f.SimTimeNs;
            ImageCount = (int)f.ImageCount;
        }

        /// <summary>Image <paramref name="index"/> in camera order.</summary>
        public Image GetImage(int index)
        {
            return host.GetImage(AgentId, index);
        }

        /// <summary>The image of the camera called <paramref name="name"/> (<c>left</c>, <c>right</c>, …).</summary>
        public Image GetImage(string name)
        {
            return host.GetImage(AgentId, host.CameraIndex(AgentId, name));
        }

        /// <summary>Copies <paramref name="sensors"/> into the header and publishes the frame.</summary>
        public void Publish(ref Sensors sensors)
        {
            host.Publish(AgentId, ref sensors);
        }

        /// <summary>Returns the frame unpublished: the agent gets nothing this cycle.</summary>
        public void Discard()
        {
            host.DiscardFrame(AgentId);
        }
    }

    /// <summary>
    /// One agent's part of the cycle just collected. <see cref="Commands"/> points into the
    /// library's memory and is valid until <see cref="Host.EndCycle"/> (a ref struct, so it
    /// cannot be kept longer by mistake).
    /// </summary>
    public readonly ref partial struct AgentReport
    {
        readonly Host host;
        public readonly uint AgentId;
        public readonly AgentOutcome Outcome;
        /// <summary>The commands, in the order the agent sent them.</summary>
        public readonly ReadOnlySpan<MotorCommand> Commands;
        /// <summary>The agent was evicted during this cycle (process died or disconnected),
        /// also when its stop had arrived first.</summary>
        public readonly bool Evicted;
        /// <summary>The agent rejoined in this cycle (its first frame since an eviction or
        /// a leave).</summary>
        public readonly bool Rejoined;
        /// <summary>The newest cycle whose frame the agent acknowledged having read, -1
        /// before its first acknowledgement (and after an eviction).</summary>
        public readonly long ReadCycle;
        /// <summary>The agent left the session gracefully during this cycle (its SDK's
        /// <c>close()</c> said so): not a fault, not evicted; its id is free for a new
        /// connection, which takes part from the next cycle. If its stop had arrived first,
        /// <see cref="Outcome"/> stays <see cref="AgentOutcome.Stopped"/>, else it is
        /// <see cref="AgentOutcome.Left"/>.</summary>
        public readonly bool Left;
        /// <summary>The host waited for the agent's stop past the stop timeout in this cycle
        /// (its <c>wait_for_stop</c> is <c>"alive"</c> and it stayed connected): a slow
        /// agent, reported, not timed out.</summary>
        public readonly bool Slow;

        internal unsafe AgentReport(Host host, NativeStructs.AgentReport r)
        {
            this.host = host;
            AgentId = r.AgentId;
            Outcome = r.Outcome;
            Commands = r.Commands == null
                ? ReadOnlySpan<MotorCommand>.Empty
                : new ReadOnlySpan<MotorCommand>(r.Commands, (int)r.CommandCount);
            Evicted = r.Evicted != 0;
            Rejoined = r.Rejoined != 0;
            ReadCycle = r.ReadCycle;
            Left = r.Left != 0;
            Slow = r.Slow != 0;
        }

        /// <summary>A copy of everything but the commands: a plain struct that may be kept,
        /// stored or captured in a lambda.</summary>
        public AgentSummary Summary
        {
            get { return new AgentSummary(AgentId, Outcome, Commands.Length, Evicted, Rejoined, ReadCycle, Left, Slow); }
        }
    }

    /// <summary>
    /// One agent's part of a cycle without its commands (<see cref="AgentReport.Summary"/>,
    /// <see cref="Host.GetSummary"/>): a copyable struct, unlike the
    /// <see cref="AgentReport"/> ref struct, so it can be used in lambdas and kept.
    /// </summary>
    public readonly struct AgentSummary
    {
        public readonly uint AgentId;
        public readonly AgentOutcome Outcome;
        /// <summary>How many commands the agent sent this cycle.</summary>
        public readonly int CommandCount;
        /// <summary>See <see cref="AgentReport.Evicted"/>.</summary>
        public readonly bool Evicted;
        /// <summary>See <see cref="AgentReport.Rejoined"/>.</summary>
        public readonly bool Rejoined;
        /// <summary>See <see cref="AgentReport.ReadCycle"/>.</summary>
        public readonly long ReadCycle;
        /// <summary>See <see cref="AgentReport.Left"/>.</summary>
        public readonly bool Left;
        /// <summary>See <see cref="AgentReport.Slow"/>.</summary>
        public readonly bool Slow;

        /// <summary>A summary that neither left nor was slow (the constructor before
        /// <see cref="Left"/> and <see cref="Slow"/> existed).</summary>
        public AgentSummary(uint agentId, AgentOutcome outcome, int commandCount, bool evicted, bool rejoined, long readCycle)
            : this(agentId, outcome, commandCount, evicted, rejoined, readCycle, false, false)
        {
        }

        public AgentSummary(uint agentId, AgentOutcome outcome, int commandCount, bool evicted, bool rejoined, long readCycle,
            bool left, bool slow)
        {
            AgentId = agentId;
            Outcome = outcome;
            CommandCount = commandCount;
            Evicted = evicted;
            Rejoined = rejoined;
            ReadCycle = readCycle;
            Left = left;
            Slow = slow;
        }

        public override string ToString()
        {
            return string.Format("agent {0}: {1}, {2} commands{3}{4}{5}{6}", AgentId, Outcome, CommandCount,
                Evicted ? ", evicted" : "", Rejoined ? ", rejoined" : "", Left ? ", left" : "", Slow ? ", slow" : "");
        }
    }

    /// <summary>One agent of the config.</summary>
    public sealed class AgentInfo
    {
        public uint Id { get; internal set; }
        public CameraInfo[] Cameras { get; internal set; }
        /// <summary>Its vectors (<c>[[agent.vector]]</c>), in config order.</summary>
        public VectorSpec[] Vectors { get; internal set; }
        /// <summary>Its actions (<c>[[agent.action]]</c>), in config order.</summary>
        public ActionSpec[] Actions { get; internal set; }
    }

    /// <summary>
    /// The host side of a vrsync session, over libvrsync_host: create it from the config
    /// file the agents use, wait for the agents, then run cycles (see the file header).
    /// Not thread-safe: use it on the thread that created it. Dispose it (Unity:
    /// <c>OnDestroy</c> / <c>OnApplicationQuit</c>) to close the session; agents then end
    /// cleanly.
    /// </summary>
    public sealed partial class Host : IDisposable
    {
        readonly HostHandle handle;
        readonly AgentInfo[] agents;

        static bool layoutChecked;

        /// <summary>Creates the host of the session in <paramref name="configPath"/>.</summary>
        /// <exception cref="VrsyncException">Bad config (<see cref="Status.Config"/>), shared
        /// memory or port trouble (<see cref="Status.Create"/>), a library built for
        /// other struct layouts.</exception>
        public Host(string configPath)
        {
            if (configPath == null)
                throw new ArgumentNullException("configPath");
            CheckLayout();
            HostHandle h;
            Status st = Native.vrs_host_create(Native.Utf8z(configPath), out h);
            if (st != Status.Ok)
            {
                h.Dispose();
                throw Error(st, "vrs_host_create");
            }
            handle = h;
            HostInfo info = Info;
            agents = new AgentInfo[info.AgentCount];
            for (uint i = 0; i < info.AgentCount; i++)
            {
                NativeStructs.AgentInfo a;
                Check(Native.vrs_host_agent_info(handle, i, out a), "vrs_host_agent_info");
                var cameras = new CameraInfo[a.CameraCount];
                for (uint c = 0; c < a.CameraCount; c++)
                    Check(Native.vrs_host_camera(handle, a.AgentId, c, out cameras[c]), "vrs_host_camera");
                agents[i] = new AgentInfo { Id = a.AgentId, Cameras = cameras };
                LoadChannels(agents[i]);
            }
        }

        /// <summary>Sends the library's log to stderr (Unity: the player log / Editor.log).
        /// <paramref name="filter"/> like <c>RUST_LOG</c> (<c>"info"</c>); null: <c>RUST_LOG</c> or <c>"warn"</c>.</summary>
        public static void InitLogging(string filter)
        {
            Check(Native.vrs_host_init_logging(filter == null ? null : Native.Utf8z(filter)),
                "vrs_host_init_logging");
        }

        /// <summary>The library version.</summary>
        public static string LibraryVersion
        {
            get { return Native.Utf8(Native.vrs_host_version()); }
        }

        /// <summary>
        /// Compares every struct of this binding with the library's (<c>vrs_host_sizeof_*</c>)
        /// and throws if one differs: a binding and a library from different versions.
        /// Called by the constructor; returns the table for tests.
        /// </summary>
        public static string[] CheckLayout()
        {
            var rows = new[]
            {
                Row("vrs_host_sensors_t", typeof(Sensors), Native.vrs_host_sizeof_sensors()),
                Row("vrs_host_frame_t", typeof(NativeStructs.Frame), Native.vrs_host_sizeof_frame()),
                Row("vrs_host_image_t", typeof(NativeStructs.Image), Native.vrs_host_sizeof_image()),
                Row("vrs_host_camera_t", typeof(CameraInfo), Native.vrs_host_sizeof_camera()),
                Row("vrs_host_agent_info_t", typeof(NativeStructs.AgentInfo), Native.vrs_host_sizeof_agent_info()),
                Row("vrs_host_info_t", typeof(HostInfo), Native.vrs_host_sizeof_info()),
                Row("vrs_host_cycle_t", typeof(CycleResult), Native.vrs_host_sizeof_cycle()),
                Row("vrs_host_command_t", typeof(MotorCommand), Native.vrs_host_sizeof_command()),
                Row("vrs_host_agent_report_t", typeof(NativeStructs.AgentReport), Native.vrs_host_sizeof_agent_report()),
                Row("vrs_host_stats_t", typeof(HostStats), Native.vrs_host_sizeof_stats()),
            };
            var channelRows = ChannelLayoutRows();
            Array.Resize(ref rows, rows.Length + channelRows.Length);
            channelRows.CopyTo(rows, rows.Length - channelRows.Length);
            foreach (var r in rows)
                if (r.StartsWith("MISMATCH"))
                    throw new VrsyncException(Status.InvalidArgument, "Vrsync.Host.CheckLayout",
                        r + ": the C# binding and libvrsync_host " + LibraryVersion + " do not match");
            layoutChecked = true;
            return rows;
        }

        static string Row(string cName, Type type, UIntPtr native)
        {
            int managed = Marshal.SizeOf(type);
            ulong n = native.ToUInt64();
            return string.Format("{0} {1} sizeof C {2} C# {3}", (ulong)managed == n ? "ok" : "MISMATCH",
                cName, n, managed);
        }

        internal static bool LayoutChecked
        {
            get { return layoutChecked; }
        }

        /// <summary>The session and the current cycle.</summary>
        public HostInfo Info
        {
            get
            {
                HostInfo info;
                Check(Native.vrs_host_info(Handle, out info), "vrs_host_info");
                return info;
            }
        }

        /// <summary>The agents of the config, ascending ids, with their cameras.</summary>
        public AgentInfo[] Agents
        {
            get { return agents; }
        }

        /// <summary>Whether agent <paramref name="agentId"/> is connected now; a TCP agent whose link
        /// was lost counts as connected while its place is held for its return
        /// (<c>[sync] resume_window</c>).</summary>
        public bool IsConnected(uint agentId)
        {
            for (uint i = 0; i < agents.Length; i++)
            {
                if (agents[i].Id != agentId)
                    continue;
                NativeStructs.AgentInfo a;
                Check(Native.vrs_host_agent_info(Handle, i, out a), "vrs_host_agent_info");
                return a.Connected != 0;
            }
            throw new VrsyncException(Status.UnknownAgent, "Vrsync.Host.IsConnected",
                "agent " + agentId + " is not part of this session");
        }

        /// <summary>Camera <paramref name="index"/> of agent <paramref name="agentId"/> (size,
        /// format, fields of view) to create render targets from.</summary>
        public CameraInfo GetCamera(uint agentId, int index)
        {
            return AgentById(agentId).Cameras[index];
        }

        internal int CameraIndex(uint agentId, string name)
        {
            var cameras = AgentById(agentId).Cameras;
            for (int i = 0; i < cameras.Length; i++)
                if (cameras[i].Name == name)
                    return i;
            throw new VrsyncException(Status.InvalidArgument, "Vrsync.SensorFrame.GetImage",
                string.Format("agent {0} has no camera named \"{1}\"", agentId, name));
        }

        AgentInfo AgentById(uint agentId)
        {
            foreach (var a in agents)
                if (a.Id == agentId)
                    return a;
            throw new VrsyncException(Status.UnknownAgent, "Vrsync.Host",
                "agent " + agentId + " is not part of this session");
        }

        /// <summary>
        /// Waits up to <paramref name="timeoutSeconds"/> (negative: the config's
        /// connect_timeout; 0: just checks) until every agent is connected. False with the
        /// missing ids otherwise; wait again or run without them. Call before the first cycle.
        /// </summary>
        public bool TryWaitForAgents(double timeoutSeconds, out uint[] missing)
        {
            if (double.IsNaN(timeoutSeconds))
                throw new ArgumentOutOfRangeException("timeoutSeconds", "NaN is not a timeout");
            // The C API counts milliseconds: round up, so a positive wait is never 0.
            long timeoutMs = timeoutSeconds < 0 ? -1
                : (long)Math.Min(Math.Ceiling(timeoutSeconds * 1000.0), long.MaxValue / 2);
            uint[] ids = new uint[Math.Max(agents.Length, 1)];
            uint count;
            Status st = Native.vrs_host_wait_for_agents(Handle, timeoutMs, ids, (uint)ids.Length, out count);
            if (st == Status.Ok)
            {
                missing = new uint[0];
                return true;
            }
            if (st == Status.Timeout)
            {
                missing = new uint[Math.Min(count, (uint)ids.Length)];
                Array.Copy(ids, missing, missing.Length);
                return false;
            }
            throw Error(st, "vrs_host_wait_for_agents");
        }

        /// <summary>Like <see cref="TryWaitForAgents"/>, throwing
        /// <see cref="AgentsMissingException"/> when agents are missing.</summary>
        public void WaitForAgents(double timeoutSeconds)
        {
            uint[] missing;
            if (!TryWaitForAgents(timeoutSeconds, out missing))
                throw new AgentsMissingException(missing, Native.LastError());
        }

        /// <summary>Frame 1: loans agent <paramref name="agentId"/>'s sensor frame of the
        /// current cycle (one per agent and cycle).</summary>
        public SensorFrame LoanFrame(uint agentId)
        {
            NativeStructs.Frame f;
            Check(Native.vrs_host_loan_frame(Handle, agentId, out f), "vrs_host_loan_frame");
            return new SensorFrame(this, f);
        }

        /// <summary>Image <paramref name="index"/> of agent <paramref name="agentId"/>'s loaned frame.</summary>
        public Image GetImage(uint agentId, int index)
        {
            NativeStructs.Image image;
            Check(Native.vrs_host_frame_image(Handle, agentId, (uint)index, out image), "vrs_host_frame_image");
            return new Image(image);
        }

        /// <summary>Frame 1: copies <paramref name="sensors"/> into agent
        /// <paramref name="agentId"/>'s loaned frame and publishes it.</summary>
        public void Publish(uint agentId, ref Sensors sensors)
        {
            Check(Native.vrs_host_publish(Handle, agentId, ref sensors), "vrs_host_publish");
        }

        /// <summary>Returns agent <paramref name="agentId"/>'s loaned frame unpublished.</summary>
        public void DiscardFrame(uint agentId)
        {
            Check(Native.vrs_host_discard_frame(Handle, agentId), "vrs_host_discard_frame");
        }

        /// <summary>Frame 1, last: one broadcast start (the original's MsgStartSync) to
        /// every agent. Every loaned frame must be published or discarded.</summary>
        public void Start()
        {
            Check(Native.vrs_host_start(Handle), "vrs_host_start");
        }

        /// <summary>
        /// Frame 2: blocks until every agent whose frame was published sent its stop, or
        /// the config's stop_timeout passed (one deadline for all agents). A missing stop
        /// is an <see cref="AgentOutcome.TimedOut"/> in that agent's report, not an
        /// exception. Read the reports with <see cref="GetReport"/>, then
        /// <see cref="EndCycle"/>.
        /// </summary>
        public CycleResult Collect()
        {
            CycleResult c;
            Check(Native.vrs_host_collect(Handle, out c), "vrs_host_collect");
            return c;
        }

        /// <summary>Report <paramref name="index"/> (<c>0..AgentCount</c>, agent id order) of
        /// the cycle just collected.</summary>
        public AgentReport GetReport(int index)
        {
            NativeStructs.AgentReport r;
            Check(Native.vrs_host_agent_report(Handle, (uint)index, out r), "vrs_host_agent_report");
            return new AgentReport(this, r);
        }

        /// <summary>The report of agent <paramref name="agentId"/> in the cycle just collected
        /// (by id, where <see cref="GetReport"/> goes by position).</summary>
        /// <exception cref="VrsyncException"><see cref="Status.UnknownAgent"/> for an id not in
        /// the config.</exception>
        public AgentReport GetReportById(uint agentId)
        {
            NativeStructs.AgentReport r;
            Check(Native.vrs_host_agent_report_by_id(Handle, agentId, out r), "vrs_host_agent_report_by_id");
            return new AgentReport(this, r);
        }

        /// <summary>The summary of agent <paramref name="agentId"/>'s part of the cycle just
        /// collected: a copyable struct (see <see cref="AgentSummary"/>).</summary>
        public AgentSummary GetSummary(uint agentId)
        {
            return GetReportById(agentId).Summary;
        }

        /// <summary>A copy of command <paramref name="commandIndex"/> of report
        /// <paramref name="agentIndex"/> (no unsafe memory involved).</summary>
        public MotorCommand GetCommand(int agentIndex, int commandIndex)
        {
            MotorCommand c;
            Check(Native.vrs_host_command(Handle, (uint)agentIndex, (uint)commandIndex, out c), "vrs_host_command");
            return c;
        }

        /// <summary>How many of agent <paramref name="agentId"/>'s commands this cycle the
        /// simulator rejected; the agent sees it in its next frame.</summary>
        public void SetRejected(uint agentId, uint rejected)
        {
            Check(Native.vrs_host_set_rejected(Handle, agentId, rejected), "vrs_host_set_rejected");
        }

        /// <summary>Ends the collected cycle (report spans become invalid).</summary>
        public void EndCycle()
        {
            Check(Native.vrs_host_end_cycle(Handle), "vrs_host_end_cycle");
        }

        /// <summary>Counters since the host was created.</summary>
        public HostStats Stats
        {
            get
            {
                HostStats s;
                Check(Native.vrs_host_stats(Handle, out s), "vrs_host_stats");
                return s;
            }
        }

        /// <summary>Destroys the host and closes the session. Idempotent.</summary>
        public void Dispose()
        {
            handle.Dispose();
        }

        HostHandle Handle
        {
            get
            {
                if (handle.IsClosed)
                    throw new ObjectDisposedException("Vrsync.Host");
                return handle;
            }
        }

        static void Check(Status st, string call)
        {
            if (st < Status.Ok)
                throw Error(st, call);
        }

        static VrsyncException Error(Status st, string call)
        {
            return new VrsyncException(st, call, Native.LastError());
        }
    }
}
