// vrsync C# binding: channels ([[agent.vector]], [[agent.action]]) over the host C ABI.
//
//   frame 1: Span<float> joints = frame.Vector("joints");  write it (shared memory on shm)
//            before frame.Publish(...)
//   frame 2: AgentReport r = host.GetReportById(id);
//            ActionValue torque = r.Action("torque");      torque.Values (ReadOnlySpan<float>)
//            ActionValue gear = r.Action("gear");          gear.Choice
//            Kind == ActionKind.None: the agent sent nothing for it this cycle.
// The specs of every agent's channels are in Host.Agents[i].Vectors / .Actions.
// Lookups by name convert the name to UTF-8 on each call; the index overloads
// (Vector(int), Action(int)) allocate nothing.

using System;
using System.Runtime.InteropServices;

namespace Vrsync
{
    /// <summary>What an action holds, or what an agent sent for it in a cycle
    /// (<c>vrs_host_action_kind_t</c>).</summary>
    public enum ActionKind : uint
    {
        /// <summary>Nothing sent this cycle (a value failing the config's checks never
        /// shows up: see <see cref="AgentReport.ActionsRejected"/>).</summary>
        None = 0,
        /// <summary>Continuous: <see cref="ActionSpec.Length"/> floats within their bounds.</summary>
        Box = 1,
        /// <summary>Discrete: a choice in <c>0..</c><see cref="ActionSpec.N"/>.</summary>
        Discrete = 2,
    }

    /// <summary>One vector (<c>[[agent.vector]]</c>) of an agent, from the config.</summary>
    public sealed class VectorSpec
    {
        public string Name { get; internal set; }
        /// <summary>Index in the agent's vector list (<see cref="SensorFrame.Vector(int)"/>).</summary>
        public int Index { get; internal set; }
        /// <summary>Number of floats.</summary>
        public int Length { get; internal set; }
        /// <summary>Observation bounds, for the agent's information (not enforced);
        /// infinite where the config gives none.</summary>
        public float[] Low { get; internal set; }
        public float[] High { get; internal set; }
    }

    /// <summary>One action (<c>[[agent.action]]</c>) of an agent, from the config.</summary>
    public sealed class ActionSpec
    {
        public string Name { get; internal set; }
        /// <summary>Index in the agent's action list (<see cref="AgentReport.Action(int)"/>).</summary>
        public int Index { get; internal set; }
        /// <summary><see cref="ActionKind.Box"/> or <see cref="ActionKind.Discrete"/>.</summary>
        public ActionKind Kind { get; internal set; }
        /// <summary>Continuous: number of floats; discrete: 0.</summary>
        public int Length { get; internal set; }
        /// <summary>Discrete: number of choices; continuous: 0.</summary>
        public uint N { get; internal set; }
        /// <summary>Continuous: the bounds every value is checked against; discrete: empty.</summary>
        public float[] Low { get; internal set; }
        public float[] High { get; internal set; }
    }

    /// <summary>
    /// What an agent sent for one action in the cycle just collected: the last complete
    /// value of the cycle, already checked against the config. <see cref="Values"/> points
    /// into the library's memory and is valid until <see cref="Host.EndCycle"/> (a ref
    /// struct, so it cannot be kept longer by mistake: copy with <see cref="ToArray"/>).
    /// </summary>
    public readonly ref struct ActionValue
    {
        /// <summary><see cref="ActionKind.None"/> when the agent sent nothing for it.</summary>
        public readonly ActionKind Kind;
        /// <summary>Index in the agent's action list.</summary>
        public readonly int Index;
        /// <summary>Continuous: the floats; otherwise empty.</summary>
        public readonly ReadOnlySpan<float> Values;
        /// <summary>Discrete: the choice; otherwise 0.</summary>
        public readonly uint Choice;

        internal unsafe ActionValue(NativeStructs.ActionValue v)
        {
            Kind = v.Kind;
            Index = (int)v.Index;
            Values = v.Values == null ? ReadOnlySpan<float>.Empty : new ReadOnlySpan<float>(v.Values, (int)v.Length);
            Choice = v.Choice;
        }

        /// <summary>Whether the agent sent a value this cycle.</summary>
        public bool HasValue
        {
            get { return Kind != ActionKind.None; }
        }

        /// <summary>A copy of <see cref="Values"/>, to keep past the cycle.</summary>
        public float[] ToArray()
        {
            return Values.ToArray();
        }
    }

    public readonly partial struct SensorFrame
    {
        /// <summary>Most vectors per agent (<c>VRS_HOST_MAX_VECTORS</c>).</summary>
        public const int MaxVectors = 8;
        /// <summary>Size of a C channel name field: 16 bytes of UTF-8 and a NUL
        /// (<c>VRS_HOST_CHANNEL_NAME_SIZE</c>).</summary>
        public const int ChannelNameSize = 17;

        /// <summary>The vector called <paramref name="name"/>, writable, straight into the
        /// loaned frame (on shared memory, the memory the agent reads). It holds an older
        /// frame's values until written: write all of it. Valid until the frame is published
        /// or discarded.</summary>
        /// <exception cref="VrsyncException"><see cref="Status.UnknownChannel"/> when the agent
        /// has no vector of that name.</exception>
        public Span<float> Vector(string name)
        {
            return host.GetVector(AgentId, name);
        }

        /// <summary>Vector <paramref name="index"/> in config order (as <see cref="Vector(string)"/>).</summary>
        public Span<float> Vector(int index)
        {
            return host.GetVector(AgentId, index);
        }
    }

    public readonly ref partial struct AgentReport
    {
        /// <summary>Most actions per agent (<c>VRS_HOST_MAX_ACTIONS</c>).</summary>
        public const int MaxActions = 8;

        /// <summary>What the agent sent for the action called <paramref name="name"/> this
        /// cycle (<see cref="ActionKind.None"/>: nothing).</summary>
        /// <exception cref="VrsyncException"><see cref="Status.UnknownChannel"/> when the agent
        /// has no action of that name.</exception>
        public ActionValue Action(string name)
        {
            return host.GetAction(AgentId, name);
        }

        /// <summary>Action <paramref name="index"/> in config order (as <see cref="Action(string)"/>).</summary>
        public ActionValue Action(int index)
        {
            return host.GetAction(AgentId, index);
        }

        /// <summary>The agent's action values refused this cycle (unknown action, wrong
        /// length, out of bounds, not finite, a choice out of range): none was applied.</summary>
        public uint ActionsRejected
        {
            get { return host.GetActionsRejected(AgentId); }
        }
    }

    public sealed partial class Host
    {
        /// <summary>Agent <paramref name="agentId"/>'s vector called <paramref name="name"/>
        /// in its loaned frame (see <see cref="SensorFrame.Vector(string)"/>).</summary>
        public unsafe Span<float> GetVector(uint agentId, string name)
        {
            if (name == null)
                throw new ArgumentNullException("name");
            NativeStructs.Vector v;
            Check(Native.vrs_host_frame_vector_by_name(Handle, agentId, Native.Utf8z(name), out v),
                "vrs_host_frame_vector_by_name");
            return new Span<float>(v.Data, (int)v.Length);
        }

        /// <summary>Agent <paramref name="agentId"/>'s vector <paramref name="index"/> in its
        /// loaned frame.</summary>
        public unsafe Span<float> GetVector(uint agentId, int index)
        {
            NativeStructs.Vector v;
            Check(Native.vrs_host_frame_vector(Handle, agentId, (uint)index, out v), "vrs_host_frame_vector");
            return new Span<float>(v.Data, (int)v.Length);
        }

        /// <summary>What agent <paramref name="agentId"/> sent for its action
        /// <paramref name="name"/> in the cycle just collected (see <see cref="ActionValue"/>).</summary>
        public ActionValue GetAction(uint agentId, string name)
        {
            if (name == null)
                throw new ArgumentNullException("name");
            NativeStructs.ActionValue v;
            Check(Native.vrs_host_action_by_name(Handle, agentId, Native.Utf8z(name), out v), "vrs_host_action_by_name");
            return new ActionValue(v);
        }

        /// <summary>What agent <paramref name="agentId"/> sent for its action
        /// <paramref name="index"/> (config order) in the cycle just collected.</summary>
        public ActionValue GetAction(uint agentId, int index)
        {
            NativeStructs.ActionValue v;
            Check(Native.vrs_host_action(Handle, agentId, (uint)index, out v), "vrs_host_action");
            return new ActionValue(v);
        }

        /// <summary>Agent <paramref name="agentId"/>'s action values refused in the cycle just
        /// collected (the total: <see cref="HostStats.ActionsRejected"/>).</summary>
        public uint GetActionsRejected(uint agentId)
        {
            uint n;
            Check(Native.vrs_host_actions_rejected(Handle, agentId, out n), "vrs_host_actions_rejected");
            return n;
        }

        /// <summary>Reads agent <paramref name="agentId"/>'s channel specs from the library.</summary>
        unsafe void LoadChannels(AgentInfo agent)
        {
            uint vectors, actions;
            Check(Native.vrs_host_channel_counts(Handle, agent.Id, out vectors, out actions), "vrs_host_channel_counts");
            agent.Vectors = new VectorSpec[vectors];
            for (uint i = 0; i < vectors; i++)
            {
                NativeStructs.VectorSpec s;
                Check(Native.vrs_host_vector_spec(Handle, agent.Id, i, out s), "vrs_host_vector_spec");
                agent.Vectors[i] = new VectorSpec
                {
                    Name = Native.Utf8(s.Name, SensorFrame.ChannelNameSize),
                    Index = (int)s.Index,
                    Length = (int)s.Length,
                    Low = Floats(s.Low, s.Length),
                    High = Floats(s.High, s.Length),
                };
            }
            agent.Actions = new ActionSpec[actions];
            for (uint i = 0; i < actions; i++)
            {
                NativeStructs.ActionSpec s;
                Check(Native.vrs_host_action_spec(Handle, agent.Id, i, out s), "vrs_host_action_spec");
                agent.Actions[i] = new ActionSpec
                {
                    Name = Native.Utf8(s.Name, SensorFrame.ChannelNameSize),
                    Index = (int)s.Index,
                    Kind = s.Kind,
                    Length = (int)s.Length,
                    N = s.N,
                    Low = Floats(s.Low, s.Length),
                    High = Floats(s.High, s.Length),
                };
            }
        }

        static unsafe float[] Floats(float* p, uint n)
        {
            var a = new float[p == null ? 0 : n];
            for (int i = 0; i < a.Length; i++)
                a[i] = p[i];
            return a;
        }

        static string[] ChannelLayoutRows()
        {
            return new[]
            {
                Row("vrs_host_vector_t", typeof(NativeStructs.Vector), Native.vrs_host_sizeof_vector()),
                Row("vrs_host_vector_spec_t", typeof(NativeStructs.VectorSpec), Native.vrs_host_sizeof_vector_spec()),
                Row("vrs_host_action_spec_t", typeof(NativeStructs.ActionSpec), Native.vrs_host_sizeof_action_spec()),
                Row("vrs_host_action_value_t", typeof(NativeStructs.ActionValue), Native.vrs_host_sizeof_action_value()),
            };
        }
    }

    public static unsafe partial class NativeStructs
    {
        [StructLayout(LayoutKind.Sequential)]
        public struct Vector
        {
            public float* Data;
            public uint Length;
            public uint Index;
            public fixed byte Name[SensorFrame.ChannelNameSize];
        }

        [StructLayout(LayoutKind.Sequential)]
        public struct VectorSpec
        {
            public float* Low;
            public float* High;
            public uint Length;
            public uint Index;
            public fixed byte Name[SensorFrame.ChannelNameSize];
        }

        [StructLayout(LayoutKind.Sequential)]
        public struct ActionSpec
        {
            public float* Low;
            public float* High;
            public uint Length;
            public uint N;
            public ActionKind Kind;
            public uint Index;
            public fixed byte Name[SensorFrame.ChannelNameSize];
        }

        [StructLayout(LayoutKind.Sequential)]
        public struct ActionValue
        {
            public float* Values;
            public uint Length;
            public uint Choice;
            public ActionKind Kind;
            public uint Index;
            public fixed byte Name[SensorFrame.ChannelNameSize];
        }
    }

    public static unsafe partial class Native
    {
        [DllImport(Lib)] public static extern UIntPtr vrs_host_sizeof_vector();
        [DllImport(Lib)] public static extern UIntPtr vrs_host_sizeof_vector_spec();
        [DllImport(Lib)] public static extern UIntPtr vrs_host_sizeof_action_spec();
        [DllImport(Lib)] public static extern UIntPtr vrs_host_sizeof_action_value();

        [DllImport(Lib)] public static extern Status vrs_host_channel_counts(HostHandle host, uint agentId, out uint vectorCount, out uint actionCount);
        [DllImport(Lib)] public static extern Status vrs_host_vector_spec(HostHandle host, uint agentId, uint index, out NativeStructs.VectorSpec spec);
        [DllImport(Lib)] public static extern Status vrs_host_action_spec(HostHandle host, uint agentId, uint index, out NativeStructs.ActionSpec spec);
        [DllImport(Lib)] public static extern Status vrs_host_frame_vector(HostHandle host, uint agentId, uint index, out NativeStructs.Vector vector);
        [DllImport(Lib)] public static extern Status vrs_host_frame_vector_by_name(HostHandle host, uint agentId, byte[] name, out NativeStructs.Vector vector);
        [DllImport(Lib)] public static extern Status vrs_host_action(HostHandle host, uint agentId, uint index, out NativeStructs.ActionValue action);
        [DllImport(Lib)] public static extern Status vrs_host_action_by_name(HostHandle host, uint agentId, byte[] name, out NativeStructs.ActionValue action);
        [DllImport(Lib)] public static extern Status vrs_host_actions_rejected(HostHandle host, uint agentId, out uint rejected);
    }
}
