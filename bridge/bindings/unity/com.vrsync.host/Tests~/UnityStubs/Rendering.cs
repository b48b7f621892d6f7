// Stubs of UnityEngine.Rendering.AsyncGPUReadback / AsyncGPUReadbackRequest (see
// UnityEngine.cs for what these stubs are). A request copies the texture's bytes, converted
// to the requested TextureFormat and in the texture's row order (bottom row first), into
// the destination NativeArray -- not when it is made but when the "GPU" finishes it: at
// WaitForCompletion() or at the end of the stub player's frame (a frame later, as in Unity).

using System;
using System.Collections.Generic;
using System.Runtime.InteropServices;
using Unity.Collections;
using Unity.Collections.LowLevel.Unsafe;

namespace UnityEngine.Rendering
{
    public struct AsyncGPUReadbackRequest
    {
        readonly AsyncGPUReadback.Pending pending;

        internal AsyncGPUReadbackRequest(AsyncGPUReadback.Pending p) { pending = p; }

        public bool done { get { return pending == null || pending.Done; } }
        public bool hasError { get { return pending == null || pending.Error; } }
        public int width { get { return pending == null ? 0 : pending.Width; } }
        public int height { get { return pending == null ? 0 : pending.Height; } }
        public int layerDataSize { get { return pending == null ? 0 : pending.Bytes.Length; } }

        public void WaitForCompletion()
        {
            if (pending != null)
                pending.Complete();
        }

        public void Update() { }
    }

    public static class AsyncGPUReadback
    {
        internal sealed class Pending
        {
            public IntPtr Destination;
            public int DestinationBytes;
            public byte[] Bytes;
            public int Width, Height;
            public bool Done, Error;
            public Action<AsyncGPUReadbackRequest> Callback;

            public void Complete()
            {
                if (Done)
                    return;
                Done = true;
                queue.Remove(this);
                if (!Error)
                    Marshal.Copy(Bytes, 0, Destination, Bytes.Length);
                StubCompleted++;
                if (Callback != null)
                    Callback(new AsyncGPUReadbackRequest(this));
            }
        }

        static readonly List<Pending> queue = new List<Pending>();

        /// <summary>Stub only: requests completed so far.</summary>
        public static int StubCompleted;

        /// <summary>Stub only: requests made so far.</summary>
        public static int StubRequested;

        /// <summary>Stub only: requests refused at once (an error request).</summary>
        public static int StubRefused;

        /// <summary>Stub only: formats a request refuses (hasError at once), to test a
        /// platform without that conversion.</summary>
        public static readonly HashSet<TextureFormat> StubUnsupported = new HashSet<TextureFormat>();

        public static unsafe AsyncGPUReadbackRequest RequestIntoNativeArray<T>(ref NativeArray<T> output, Texture src,
            int mipIndex, TextureFormat dstFormat, Action<AsyncGPUReadbackRequest> callback = null) where T : struct
        {
            StubRequested++;
            var rt = src as RenderTexture;
            var p = new Pending { Callback = callback, Width = src.width, Height = src.height };
            if (rt == null || mipIndex != 0 || StubUnsupported.Contains(dstFormat))
            {
                StubRefused++;
                p.Error = true;
                p.Done = true;
                return new AsyncGPUReadbackRequest(p);
            }
            // Taken now: the GPU reads the texture as it is at this point of the command stream.
            p.Bytes = StubTexture.Convert(rt, dstFormat);
            p.Destination = (IntPtr)NativeArrayUnsafeUtility.GetUnsafePtr(output);
            p.DestinationBytes = output.Length * Marshal.SizeOf(typeof(T));
            if (p.DestinationBytes < p.Bytes.Length)
            {
                // Unity: "the destination NativeArray is too small" -> an error request.
                StubRefused++;
                p.Error = true;
                p.Done = true;
                return new AsyncGPUReadbackRequest(p);
            }
            queue.Add(p);
            return new AsyncGPUReadbackRequest(p);
        }

        public static void WaitAllRequests()
        {
            StubCompleteAll();
        }

        /// <summary>Stub only: the GPU finishes every pending request (end of a frame).</summary>
        public static void StubCompleteAll()
        {
            foreach (var p in queue.ToArray())
                p.Complete();
        }
    }
}
