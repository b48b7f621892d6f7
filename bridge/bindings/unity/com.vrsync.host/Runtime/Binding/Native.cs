// vrsync C# binding: the structs and P/Invoke declarations of the host C ABI
// (bridge/ffi/include/vrsync_host.h). Every struct here mirrors one C struct field by field,
// [StructLayout(LayoutKind.Sequential)] and blittable (no bool, no string, no managed
// array), so it crosses the boundary without marshalling and a Span can point at it.
// Host.CheckLayout() compares each Marshal.SizeOf with vrs_host_sizeof_* at start.
//
// Written in the C# subset Mono's mcs (C# 7.x) and Unity (C# 9, .NET Standard 2.1) share.

using System;
using System.Runtime.InteropServices;

namespace Vrsync
{
    /// <summary>Result codes of the C ABI (<c>vrs_host_status_t</c>): 0 success, positive
    /// outcomes that are not errors, negative errors.</summary>
    public enum Status : int
    {
        Ok = 0,
        /// <summary>Agents missing after <c>WaitForAgents</c>.</summary>
        Timeout = 1,
        /// <summary>Destroy from a foreign thread: done at the owner's next call.</summary>
        Deferred = 2,
        InvalidArgument = -1,
        InvalidHandle = -2,
        WrongThread = -3,
        Config = -4,
        Create = -5,
        UnknownAgent = -6,
        WrongState = -7,
        NoFrame = -8,
        OutOfRange = -9,
        /// <summary>An agent was lost and the config's on_agent_lost is "abort" (or "wait" and it did not come back).</summary>
        AgentLost = -10,
        Transport = -12,
        Terminated = -13,
        /// <summary>The agent has no vector or action of that name.</summary>
        UnknownChannel = -14,
        Other = -98,
        Panic = -99,
    }

    /// <summary>Pixel format of an image (<c>vrs_host_pixel_format_t</c>).</summary>
    public enum PixelFormat : uint
    {
        /// <summary>8-bit R, G, B; 3 bytes per pixel (Unity <c>TextureFormat.RGB24</c>).</summary>
        Rgb8 = 0,
        /// <summary>8-bit R, G, B, A; 4 bytes per pixel (Unity <c>TextureFormat.RGBA32</c>).</summary>
        Rgba8 = 1,
        /// <summary>8-bit grey; 1 byte per pixel (Unity <c>TextureFormat.R8</c>).</summary>
        Gray8 = 2,
        /// <summary>32-bit float depth in metres (Unity <c>TextureFormat.RFloat</c>).</summary>
        Depth32f = 3,
    }

    /// <summary>Execution state of an action (the original <c>MsgActionExecutationStatus</c>).</summary>
    public enum ActionState : uint
    {
        InExecution = 0,
        Finished = 1,
        Aborted = 2,
        Walking = 3,
        Rotating = 4,
        WalkingRotating = 5,
    }

    /// <summary>How one agent's part of a cycle ended (<c>vrs_host_outcome_t</c>).</summary>
    public enum AgentOutcome : uint
    {
        /// <summary>No frame reached the agent (not connected): not waited for.</summary>
        NotAwaited = 0,
        /// <summary>The stop arrived in time.</summary>
        Stopped = 1,
        /// <summary>The stop timeout ended the cycle first. Not an error (the original's
        /// "Normal stop-sync timeout").</summary>
        TimedOut = 2,
        /// <summary>Async mode.</summary>
        Async = 3,
        /// <summary>The agent's process died or disconnected during the cycle.</summary>
        Evicted = 4,
        /// <summary>The agent left the session gracefully during the cycle (it closed its
        /// connection and said so) before its stop.</summary>
        Left = 5,
        /// <summary>An outcome this binding does not know.</summary>
        Other = 255,
    }

    /// <summary>Motor command kinds (<c>vrs_host_command_kind_t</c>). An agent may send any
    /// number: check before applying.</summary>
    public enum CommandKind : uint
    {
        /// <summary>Walk <c>Arg0</c> degrees heading (world, 0 = +z, 90 = +x) for <c>Arg1</c> metres.</summary>
        Move = 1,
        /// <summary>Turn by <c>Arg0</c> degrees (clockwise seen from above).</summary>
        Turn = 2,
        /// <summary>Walk straight to (<c>Arg0</c>, <c>Arg1</c>, <c>Arg2</c>).</summary>
        MoveTo = 3,
        CancelMove = 4,
        /// <summary>Pan left <c>Arg0</c>, pan right <c>Arg1</c>, tilt <c>Arg2</c> degrees.</summary>
        EyeMovement = 5,
        /// <summary>Fixate the world point (<c>Arg0</c>, <c>Arg1</c>, <c>Arg2</c>).</summary>
        EyeFixation = 6,
        /// <summary>Grasp object <c>ObjectId</c>.</summary>
        GraspId = 7,
        /// <summary>Grasp what is seen at left-eye pixel (<c>Arg0</c>, <c>Arg1</c>).</summary>
        GraspPos = 8,
        PointId = 9,
        PointPos = 10,
        InteractId = 11,
        InteractPos = 12,
        GraspRelease = 13,
        /// <summary>Reset the environment (<c>ObjectId</c> = reset type).</summary>
        EnvironmentReset = 14,
        /// <summary>Reset the trial (<c>ObjectId</c> = reset type).</summary>
        TrialReset = 15,
    }

    /// <summary>The transport a host runs on.</summary>
    public enum Transport : uint
    {
        Shm = 0,
        Tcp = 1,
        Zenoh = 2,
        /// <summary>The original system's protobuf/TCP protocol.</summary>
        Legacy = 3,
    }

    /// <summary>Three floats (C <c>float[3]</c>); same layout as Unity's <c>Vector3</c>.</summary>
    [StructLayout(LayoutKind.Sequential)]
    public struct Vec3
    {
        public float X, Y, Z;

        public Vec3(float x, float y, float z)
        {
            X = x;
            Y = y;
            Z = z;
        }

        public override string ToString()
        {
            return string.Format("({0:0.###}, {1:0.###}, {2:0.###})", X, Y, Z);
        }
    }

    /// <summary>A unit quaternion <c>[x, y, z, w]</c>; same layout as Unity's <c>Quaternion</c>.</summary>
    [StructLayout(LayoutKind.Sequential)]
    public struct Quat
    {
        public float X, Y, Z, W;

        public Quat(float x, float y, float z, float w)
        {
            X = x;
            Y = y;
            Z = z;
            W = w;
        }

        public static Quat Identity
        {
            get { return new Quat(0f, 0f, 0f, 1f); }
        }

        /// <summary>Rotation by <paramref name="yawDeg"/> degrees about +y (heading:
        /// 0 looks along +z, 90 along +x).</summary>
        public static Quat FromYawDeg(float yawDeg)
        {
            double half = yawDeg * Math.PI / 360.0;
            return new Quat(0f, (float)Math.Sin(half), 0f, (float)Math.Cos(half));
        }
    }

    /// <summary>Body pose (<c>vrs_host_pose_t</c>).</summary>
    [StructLayout(LayoutKind.Sequential)]
    public struct Pose
    {
        /// <summary>Metres, world frame (x right, y up, z forward).</summary>
        public Vec3 Position;
        /// <summary>Orientation. All zeros (a <c>default</c> struct) is sent as the identity.</summary>
        public Quat Rotation;
    }

    /// <summary>Grid position sensor (<c>vrs_host_grid_position_t</c>).</summary>
    [StructLayout(LayoutKind.Sequential)]
    public struct GridPosition
    {
        public Vec3 Position;
        public Vec3 RotationDeg;
    }

    /// <summary>Head motion sensor (<c>vrs_host_head_motion_t</c>).</summary>
    [StructLayout(LayoutKind.Sequential)]
    public struct HeadMotion
    {
        public Vec3 Velocity;
        public Vec3 Acceleration;
        public Vec3 AngularVelocityDeg;
        public Vec3 AngularAccelerationDeg;
    }

    /// <summary>Eye position sensor (<c>vrs_host_eye_position_t</c>).</summary>
    [StructLayout(LayoutKind.Sequential)]
    public struct EyePosition
    {
        /// <summary>Pan left, pan right, tilt, degrees.</summary>
        public Vec3 RotationDeg;
        public Vec3 RotationVelocityDeg;
    }

    /// <summary>One action status (<c>vrs_host_action_status_t</c>).</summary>
    [StructLayout(LayoutKind.Sequential)]
    public struct ActionStatus
    {
        public uint ActionId;
        public ActionState State;
    }

    /// <summary>One collision (<c>vrs_host_collision_t</c>).</summary>
    [StructLayout(LayoutKind.Sequential)]
    public struct Collision
    {
        public uint ActionId;
        public uint ColliderId;
    }

    /// <summary>
    /// The sensor data of one agent's frame (<c>vrs_host_sensors_t</c>), everything but the
    /// images: filled by the simulator and copied into the frame's header on publish.
    /// Statuses and collisions are the events since the previous frame: add them with
    /// <see cref="AddStatus"/> / <see cref="AddCollision"/>, clear them with
    /// <see cref="ClearEvents"/> after publishing.
    /// </summary>
    [StructLayout(LayoutKind.Sequential)]
    public unsafe struct Sensors
    {
        public const int MaxStatuses = 16;
        public const int MaxCollisions = 8;

        public Pose Pose;
        public float Reward;
        public GridPosition Grid;
        public HeadMotion HeadMotion;
        public EyePosition Eye;
        public uint StatusCount;
        public uint CollisionCount;
        // vrs_host_action_status_t statuses[16]: (action_id, state) pairs.
        fixed uint statuses[2 * MaxStatuses];
        // vrs_host_collision_t collisions[8]: (action_id, collider_id) pairs.
        fixed uint collisions[2 * MaxCollisions];

        /// <summary>Identity pose, everything else zero.</summary>
        public static Sensors Create()
        {
            Sensors s = default(Sensors);
            s.Pose.Rotation = Quat.Identity;
            return s;
        }

        /// <summary>Reports the state of the agent's action <paramref name="actionId"/>;
        /// false (dropped) when the table is full.</summary>
        public bool AddStatus(uint actionId, ActionState state)
        {
            if (StatusCount >= MaxStatuses)
                return false;
            fixed (uint* p = statuses)
            {
                p[2 * StatusCount] = actionId;
                p[2 * StatusCount + 1] = (uint)state;
            }
            StatusCount++;
            return true;
        }

        /// <summary>Reports a collision during action <paramref name="actionId"/>; false
        /// (dropped) when the table is full.</summary>
        public bool AddCollision(uint actionId, uint colliderId)
        {
            if (CollisionCount >= MaxCollisions)
                return false;
            fixed (uint* p = collisions)
            {
                p[2 * CollisionCount] = actionId;
                p[2 * CollisionCount + 1] = colliderId;
            }
            CollisionCount++;
            return true;
        }

        public ActionStatus GetStatus(int index)
        {
            if ((uint)index >= StatusCount)
                throw new ArgumentOutOfRangeException("index");
            fixed (uint* p = statuses)
            {
                ActionStatus s;
                s.ActionId = p[2 * index];
                s.State = (ActionState)p[2 * index + 1];
                return s;
            }
        }

        public Collision GetCollision(int index)
        {
            if ((uint)index >= CollisionCount)
                throw new ArgumentOutOfRangeException("index");
            fixed (uint* p = collisions)
            {
                Collision c;
                c.ActionId = p[2 * index];
                c.ColliderId = p[2 * index + 1];
                return c;
            }
        }

        /// <summary>Forgets the statuses and collisions (after they were published).</summary>
        public void ClearEvents()
        {
            StatusCount = 0;
            CollisionCount = 0;
        }
    }

    /// <summary>
    /// A motor command as the agent sent it (<c>vrs_host_command_t</c>, the wire layout).
    /// <see cref="Kind"/> may be any number and the arguments anything (NaN, huge): check
    /// before applying, and count the rejected ones (<see cref="Host.SetRejected"/>).
    /// </summary>
    [StructLayout(LayoutKind.Sequential)]
    public struct MotorCommand
    {
        public CommandKind Kind;
        /// <summary>The agent's id for this action: report its state in <see cref="Sensors.AddStatus"/>.</summary>
        public uint ActionId;
        /// <summary>Object id or reset type, for the kinds that take one.</summary>
        public uint ObjectId;
        uint reserved;
        public float Arg0, Arg1, Arg2, Arg3;

        /// <summary>Whether the first <paramref name="count"/> arguments are finite.</summary>
        public bool ArgsFinite(int count)
        {
            return (count < 1 || IsFinite(Arg0)) && (count < 2 || IsFinite(Arg1))
                && (count < 3 || IsFinite(Arg2)) && (count < 4 || IsFinite(Arg3));
        }

        /// <summary>How many float arguments <see cref="Kind"/> uses; -1 for an unknown kind.</summary>
        public int ArgCount
        {
            get
            {
                switch (Kind)
                {
                    case CommandKind.Turn:
                        return 1;
                    case CommandKind.Move:
                    case CommandKind.GraspPos:
                    case CommandKind.PointPos:
                    case CommandKind.InteractPos:
                        return 2;
                    case CommandKind.MoveTo:
                    case CommandKind.EyeMovement:
                    case CommandKind.EyeFixation:
                        return 3;
                    case CommandKind.CancelMove:
                    case CommandKind.GraspId:
                    case CommandKind.PointId:
                    case CommandKind.InteractId:
                    case CommandKind.GraspRelease:
                    case CommandKind.EnvironmentReset:
                    case CommandKind.TrialReset:
                        return 0;
                    default:
                        return -1;
                }
            }
        }

        /// <summary>A known kind with finite arguments (ranges are the simulator's call).</summary>
        public bool IsWellFormed
        {
            get
            {
                int n = ArgCount;
                return n >= 0 && ArgsFinite(n);
            }
        }

        static bool IsFinite(float f)
        {
            return !float.IsNaN(f) && !float.IsInfinity(f);
        }

        public override string ToString()
        {
            return string.Format("{0}#{1}(obj {2}; {3}, {4}, {5}, {6})", Kind, ActionId, ObjectId,
                Arg0, Arg1, Arg2, Arg3);
        }
    }

    /// <summary>The session (<c>vrs_host_info_t</c>).</summary>
    [StructLayout(LayoutKind.Sequential)]
    public struct HostInfo
    {
        /// <summary>Current cycle (the next frame's).</summary>
        public ulong Cycle;
        /// <summary>Raw nanoseconds of the C struct; <see cref="SimTime"/> in seconds.</summary>
        public ulong SimTimeNs;
        /// <summary>Raw nanoseconds; <see cref="SimulationTimePerFrame"/> in seconds.</summary>
        public ulong SimulationTimePerFrameNs;
        /// <summary>Raw nanoseconds; <see cref="StopTimeout"/> in seconds.</summary>
        public ulong StopTimeoutNs;
        /// <summary>Raw nanoseconds; <see cref="ConnectTimeout"/> in seconds.</summary>
        public ulong ConnectTimeoutNs;
        public uint AgentCount;
        /// <summary>1 in sync (lock-step) mode.</summary>
        public uint SyncMode;
        public Transport Transport;
        public uint TcpPort;
        public uint MaxCommandsPerCycle;
        public uint ProtocolVersion;

        /// <summary>Simulated time at the current cycle, seconds.</summary>
        public double SimTime
        {
            get { return SimTimeNs / 1e9; }
        }

        /// <summary>Simulated time per cycle (<c>simulation_time_per_frame</c>), seconds.</summary>
        public double SimulationTimePerFrame
        {
            get { return SimulationTimePerFrameNs / 1e9; }
        }

        /// <summary>How long a cycle waits for the agents' stops (<c>stop_timeout</c>), seconds.</summary>
        public double StopTimeout
        {
            get { return StopTimeoutNs / 1e9; }
        }

        /// <summary>How long the host waits for agents (<c>connect_timeout</c>), seconds.</summary>
        public double ConnectTimeout
        {
            get { return ConnectTimeoutNs / 1e9; }
        }
    }

    /// <summary>One camera of an agent, from the config (<c>vrs_host_camera_t</c>).</summary>
    [StructLayout(LayoutKind.Sequential)]
    public unsafe struct CameraInfo
    {
        /// <summary>Size of the C name field: 16 bytes of UTF-8 and a NUL.</summary>
        public const int NameSize = 17;

        public ulong Length;
        public ulong Stride;
        public uint Width;
        public uint Height;
        public PixelFormat Format;
        public float FovHorizontalDeg;
        /// <summary>Unity's <c>Camera.fieldOfView</c> is vertical: set it to this.</summary>
        public float FovVerticalDeg;
        fixed byte name[NameSize];

        public string Name
        {
            get
            {
                fixed (byte* p = name)
                    return Native.Utf8(p, NameSize);
            }
        }
    }

    /// <summary>The end of one cycle (<c>vrs_host_cycle_t</c>).</summary>
    [StructLayout(LayoutKind.Sequential)]
    public struct CycleResult
    {
        /// <summary>The cycle that ended.</summary>
        public ulong Cycle;
        /// <summary>Raw nanoseconds of the C struct; <see cref="SimTime"/> in seconds.</summary>
        public ulong SimTimeNs;
        /// <summary>Number of agent reports (<see cref="Host.GetReport"/> indices).</summary>
        public uint AgentCount;
        /// <summary>Agents whose stop missed the stop timeout (0 = lock-step held).</summary>
        public uint TimedOutAgents;
        public uint LateBatches;
        public uint CommandCount;
        /// <summary>Agents evicted during this cycle (process died or disconnected); which
        /// ones: <see cref="AgentReport.Evicted"/>.</summary>
        public uint EvictedAgents;
        /// <summary>Agents that rejoined in this cycle (their first frame since an eviction
        /// or a leave reached them); which ones: <see cref="AgentReport.Rejoined"/>.</summary>
        public uint RejoinedAgents;
        /// <summary>Agents that left the session gracefully during this cycle (their SDK's
        /// <c>close()</c> said so: not a fault, not evicted, not timed out; the id is free
        /// for a new connection, which takes part from the next cycle); which ones:
        /// <see cref="AgentReport.Left"/>.</summary>
        public uint LeftAgents;
        /// <summary>Agents the host waited for past the stop timeout in this cycle (their
        /// <c>wait_for_stop</c> is <c>"alive"</c> and they stayed connected: busy, not lost;
        /// nothing was dropped); which ones: <see cref="AgentReport.Slow"/>.</summary>
        public uint SlowAgents;

        /// <summary>Simulated time of the cycle that ended, seconds.</summary>
        public double SimTime
        {
            get { return SimTimeNs / 1e9; }
        }
    }

    /// <summary>Counters since the host was created (<c>vrs_host_stats_t</c>).</summary>
    [StructLayout(LayoutKind.Sequential)]
    public struct HostStats
    {
        public ulong Cycles;
        public ulong StopTimeouts;
        public ulong AgentTimeouts;
        public ulong LateBatches;
        public ulong FutureBatches;
        public ulong CommandsReceived;
        public ulong CommandsOverflowed;
        public ulong FramesUndelivered;
        /// <summary>Evictions (an agent evicted twice counts 2).</summary>
        public ulong Evictions;
        /// <summary>Times an evicted agent, or one that left, came back.</summary>
        public ulong Rejoins;
        /// <summary>Frames delivered to an agent.</summary>
        public ulong FramesDelivered;
        /// <summary>Frames an agent acknowledged having read; the difference to
        /// <see cref="FramesDelivered"/> was skipped (its events still reached the agent) or is
        /// still being read.</summary>
        public ulong FramesRead;
        /// <summary>Action statuses dropped because an agent's table of unacknowledged events
        /// was full (it acknowledged nothing for long).</summary>
        public ulong StatusesDropped;
        /// <summary>Collisions dropped likewise.</summary>
        public ulong CollisionsDropped;
        /// <summary>Cycles in which the host waited past the stop timeout for an agent whose
        /// <c>wait_for_stop</c> is <c>"alive"</c> (it was busy, not lost: nothing was
        /// dropped). Not stop timeouts.</summary>
        public ulong SlowStops;
        /// <summary>Graceful leaves: an agent's SDK said it leaves (<c>close()</c>, drop).
        /// Not evictions, not timeouts.</summary>
        public ulong Leaves;
        /// <summary>Peers refused or dropped before they were admitted as agents (garbage, a
        /// wrong token or protocol version, an unknown or taken id, a silent
        /// connection).</summary>
        public ulong PeersRefused;
        /// <summary>Action values refused (unknown action, wrong length, out of bounds, not
        /// finite, a choice out of range): none was applied. Per agent and cycle:
        /// <see cref="AgentReport.ActionsRejected"/>.</summary>
        public ulong ActionsRejected;
        /// <summary>Times an agent whose link was lost came back within
        /// <c>[sync] resume_window</c> and went on where it was (TCP and zenoh agents): not
        /// evictions, not rejoins.</summary>
        public ulong Resumes;
    }

    /// <summary>The raw C structs the public types are built from.</summary>
    public static unsafe partial class NativeStructs
    {
        [StructLayout(LayoutKind.Sequential)]
        public struct Frame
        {
            public ulong Cycle;
            public ulong SimTimeNs;
            public uint AgentId;
            public uint ImageCount;
        }

        [StructLayout(LayoutKind.Sequential)]
        public struct Image
        {
            public byte* Data;
            public ulong Length;
            public ulong Stride;
            public uint Width;
            public uint Height;
            public PixelFormat Format;
            public uint Camera;
            public fixed byte Name[CameraInfo.NameSize];
        }

        [StructLayout(LayoutKind.Sequential)]
        public struct AgentInfo
        {
            public uint AgentId;
            public uint CameraCount;
            public uint Connected;
            public uint Reserved;
        }

        [StructLayout(LayoutKind.Sequential)]
        public struct AgentReport
        {
            public uint AgentId;
            public AgentOutcome Outcome;
            public uint CommandCount;
            public uint Reserved;
            public MotorCommand* Commands;
            public long ReadCycle;
            public uint Evicted;
            public uint Rejoined;
            public uint Left;
            public uint Slow;
        }
    }

    /// <summary>P/Invoke declarations of libvrsync_host (vrsync_host.dll on Windows).</summary>
    public static unsafe partial class Native
    {
        /// <summary>The library name: Unity and Mono find <c>libvrsync_host.so</c>,
        /// <c>libvrsync_host.dylib</c> or <c>vrsync_host.dll</c> from it.</summary>
        public const string Lib = "vrsync_host";

        [DllImport(Lib)] public static extern IntPtr vrs_host_version();
        [DllImport(Lib)] public static extern uint vrs_host_protocol_version();
        [DllImport(Lib)] public static extern IntPtr vrs_host_last_error_message();
        [DllImport(Lib)] public static extern IntPtr vrs_host_status_name(int status);
        [DllImport(Lib)] public static extern Status vrs_host_init_logging(byte[] filter);

        [DllImport(Lib)] public static extern UIntPtr vrs_host_sizeof_sensors();
        [DllImport(Lib)] public static extern UIntPtr vrs_host_sizeof_frame();
        [DllImport(Lib)] public static extern UIntPtr vrs_host_sizeof_image();
        [DllImport(Lib)] public static extern UIntPtr vrs_host_sizeof_camera();
        [DllImport(Lib)] public static extern UIntPtr vrs_host_sizeof_agent_info();
        [DllImport(Lib)] public static extern UIntPtr vrs_host_sizeof_info();
        [DllImport(Lib)] public static extern UIntPtr vrs_host_sizeof_cycle();
        [DllImport(Lib)] public static extern UIntPtr vrs_host_sizeof_command();
        [DllImport(Lib)] public static extern UIntPtr vrs_host_sizeof_agent_report();
        [DllImport(Lib)] public static extern UIntPtr vrs_host_sizeof_stats();

        [DllImport(Lib)] public static extern Status vrs_host_create(byte[] configPath, out HostHandle host);
        // Takes the raw pointer: called from HostHandle.ReleaseHandle.
        [DllImport(Lib)] public static extern Status vrs_host_destroy(IntPtr host);
        [DllImport(Lib)] public static extern Status vrs_host_info(HostHandle host, out HostInfo info);
        [DllImport(Lib)] public static extern Status vrs_host_agent_info(HostHandle host, uint index, out NativeStructs.AgentInfo agent);
        [DllImport(Lib)] public static extern Status vrs_host_camera(HostHandle host, uint agentId, uint index, out CameraInfo camera);
        [DllImport(Lib)] public static extern Status vrs_host_wait_for_agents(HostHandle host, long timeoutMs, uint[] missing, uint missingCapacity, out uint missingCount);
        [DllImport(Lib)] public static extern Status vrs_host_loan_frame(HostHandle host, uint agentId, out NativeStructs.Frame frame);
        [DllImport(Lib)] public static extern Status vrs_host_frame_image(HostHandle host, uint agentId, uint index, out NativeStructs.Image image);
        [DllImport(Lib)] public static extern Status vrs_host_publish(HostHandle host, uint agentId, ref Sensors sensors);
        [DllImport(Lib)] public static extern Status vrs_host_discard_frame(HostHandle host, uint agentId);
        [DllImport(Lib)] public static extern Status vrs_host_start(HostHandle host);
        [DllImport(Lib)] public static extern Status vrs_host_collect(HostHandle host, out CycleResult cycle);
        [DllImport(Lib)] public static extern Status vrs_host_agent_report(HostHandle host, uint index, out NativeStructs.AgentReport report);
        [DllImport(Lib)] public static extern Status vrs_host_agent_report_by_id(HostHandle host, uint agentId, out NativeStructs.AgentReport report);
        [DllImport(Lib)] public static extern Status vrs_host_command(HostHandle host, uint agentIndex, uint commandIndex, out MotorCommand command);
        [DllImport(Lib)] public static extern Status vrs_host_set_rejected(HostHandle host, uint agentId, uint rejected);
        [DllImport(Lib)] public static extern Status vrs_host_end_cycle(HostHandle host);
        [DllImport(Lib)] public static extern Status vrs_host_stats(HostHandle host, out HostStats stats);

        /// <summary>A NUL-terminated UTF-8 copy of <paramref name="s"/> (P/Invoke's own
        /// string marshalling is ANSI on Windows).</summary>
        public static byte[] Utf8z(string s)
        {
            int n = System.Text.Encoding.UTF8.GetByteCount(s);
            byte[] bytes = new byte[n + 1];
            System.Text.Encoding.UTF8.GetBytes(s, 0, s.Length, bytes, 0);
            return bytes;
        }

        /// <summary>Up to <paramref name="max"/> bytes of UTF-8 at <paramref name="p"/>, to the first NUL.</summary>
        public static string Utf8(byte* p, int max)
        {
            if (p == null)
                return "";
            int n = 0;
            while (n < max && p[n] != 0)
                n++;
            return System.Text.Encoding.UTF8.GetString(p, n);
        }

        /// <summary>A C string owned by the library.</summary>
        public static string Utf8(IntPtr p)
        {
            return Utf8((byte*)p, int.MaxValue);
        }

        /// <summary>The calling thread's last message.</summary>
        public static string LastError()
        {
            return Utf8(vrs_host_last_error_message());
        }

        /// <summary>The C name of a status (<c>VRS_HOST_ERROR_WRONG_STATE</c>, …).</summary>
        public static string StatusName(Status status)
        {
            return Utf8(vrs_host_status_name((int)status));
        }
    }
}
