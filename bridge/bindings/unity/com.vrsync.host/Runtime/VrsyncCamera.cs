// One camera of an agent: renders into a RenderTexture of the config's size and format and
// reads it back with ONE GPU->CPU copy, straight into the loaned frame's image memory (on the
// shared-memory transport: the memory the agent reads).
//
//   Camera.Render()  ->  target (RenderTexture, Unity's rows: bottom row first)
//   Graphics.Blit(target, flipped, scale (1,-1), offset (0,1))      (on the GPU: row order)
//   AsyncGPUReadback.RequestIntoNativeArray(ref image, flipped, 0, RGB24 | RGBA32 | R8 | RFloat)
//       where `image` is a NativeArray<byte> over the loaned frame's image
//       (NativeArrayUnsafeUtility.ConvertExistingDataToNativeArray, Allocator.None)
//
// Row order and channels: vrsync images are row-major, top row first (origin top-left), as
// vr-sim renders them; rgb8 bytes are R, G, B (rgba8: R, G, B, A; gray8: one byte; depth32f:
// a native-endian float). Unity's textures and its readbacks start with the BOTTOM row, so
// the image is flipped on the GPU before the readback (flipVertically), and the readback's
// destination format puts the channels in the wire's byte order. The fallback path
// (ReadPixels, where async readback is unsupported or a format conversion is refused) reads
// into a Texture2D and copies its rows bottom-up into the loaned memory.

using System;
using Unity.Collections;
using Unity.Collections.LowLevel.Unsafe;
using UnityEngine;
using UnityEngine.Rendering;

namespace Vrsync
{
    /// <summary>How a <see cref="VrsyncCamera"/> gets its pixels from the GPU.</summary>
    public enum ReadbackMode
    {
        /// <summary>AsyncGPUReadback where the platform supports it, else ReadPixels.</summary>
        Auto,
        /// <summary>AsyncGPUReadback into the loaned frame (falls back to ReadPixels if a
        /// request fails).</summary>
        AsyncGPUReadback,
        /// <summary>Texture2D.ReadPixels (stalls the GPU), then one copy into the loaned frame.</summary>
        ReadPixels,
    }

    /// <summary>
    /// One camera of the config (<c>[[agent.camera]]</c>, by <see cref="cameraName"/>) on a
    /// Camera under its <see cref="VrsyncAgent"/>. The camera renders on demand, once per
    /// cycle (it is disabled so it does not also render every engine frame).
    /// </summary>
    [RequireComponent(typeof(Camera))]
    [DisallowMultipleComponent]
    [AddComponentMenu("vrsync/Vrsync Camera")]
    public sealed class VrsyncCamera : MonoBehaviour
    {
        [Tooltip("The name of this camera in the agent's [[agent.camera]] list of the config")]
        public string cameraName = "left";

        [Tooltip("How the pixels come back from the GPU")]
        public ReadbackMode readback = ReadbackMode.Auto;

        [Tooltip("Turn Unity's bottom-up rows into vrsync's top-down rows (keep on unless a test pattern shows your graphics API already reads top-down)")]
        public bool flipVertically = true;

        [Tooltip("Set the Camera's vertical field of view from the config")]
        public bool applyFieldOfView = true;

        Camera unityCamera;
        RenderTexture target;
        RenderTexture flipped;
        Texture2D cpuCopy;
        TextureFormat readFormat;
        bool useReadPixels;
        bool warnedFallback;

        // The capture in flight: the readback writes into the loaned frame's memory.
        bool pending;
        Image pendingImage;
        AsyncGPUReadbackRequest request;
#if ENABLE_UNITY_COLLECTIONS_CHECKS
        AtomicSafetyHandle safety;
#endif

        /// <summary>The config's camera (size, format, fields of view); set when the host starts.</summary>
        public CameraInfo Info { get; private set; }

        /// <summary>The RenderTexture the camera draws into (Unity's row order).</summary>
        public RenderTexture Target { get { return target; } }

        /// <summary>Whether this camera reads with ReadPixels (chosen, or after a refused readback).</summary>
        public bool UsesReadPixels { get { return useReadPixels; } }

        /// <summary>Images captured so far.</summary>
        public long Captures { get; private set; }

        /// <summary>Creates the render targets for <paramref name="info"/> (called by
        /// <see cref="VrsyncAgent"/> when the host starts).</summary>
        internal void Bind(CameraInfo info)
        {
            Info = info;
            unityCamera = GetComponent<Camera>();
            if (unityCamera == null)
                throw new InvalidOperationException("VrsyncCamera " + cameraName + ": no Camera on " + name);
            int w = (int)info.Width, h = (int)info.Height;
            RenderTextureFormat gpuFormat;
            switch (info.Format)
            {
                case PixelFormat.Rgb8:
                    gpuFormat = RenderTextureFormat.ARGB32;  // 8-bit R, G, B, A in memory
                    readFormat = TextureFormat.RGB24;        // R, G, B bytes: rgb8
                    break;
                case PixelFormat.Rgba8:
                    gpuFormat = RenderTextureFormat.ARGB32;
                    readFormat = TextureFormat.RGBA32;       // R, G, B, A bytes: rgba8
                    break;
                case PixelFormat.Gray8:
                    gpuFormat = RenderTextureFormat.R8;      // the red channel (e.g. a grey shader)
                    readFormat = TextureFormat.R8;
                    break;
                case PixelFormat.Depth32f:
                    gpuFormat = RenderTextureFormat.RFloat;  // metres, written by your depth shader
                    readFormat = TextureFormat.RFloat;
                    break;
                default:
                    throw new InvalidOperationException("VrsyncCamera " + cameraName + ": pixel format " + info.Format);
            }
            ReleaseTextures();
            target = new RenderTexture(w, h, 24, gpuFormat);
            target.name = "vrsync " + cameraName;
            target.Create();
            if (flipVertically)
            {
                flipped = new RenderTexture(w, h, 0, gpuFormat);
                flipped.name = "vrsync " + cameraName + " (top-down)";
                flipped.Create();
            }
            unityCamera.targetTexture = target;
            unityCamera.enabled = false;  // rendered once per cycle, by Capture
            if (applyFieldOfView && info.FovVerticalDeg > 0)
                unityCamera.fieldOfView = info.FovVerticalDeg;
            useReadPixels = readback == ReadbackMode.ReadPixels
                || (readback == ReadbackMode.Auto && !SystemInfo.supportsAsyncGPUReadback);
        }

        /// <summary>
        /// Frame 1: renders the camera and starts reading it back into
        /// <paramref name="image"/> (the loaned frame's memory, valid until the frame is
        /// published). With ReadPixels the image is complete on return.
        /// </summary>
        internal unsafe void BeginCapture(Image image)
        {
            if (pending)
                throw new InvalidOperationException("VrsyncCamera " + cameraName + ": a capture is still in flight");
            if (image.Width != (int)Info.Width || image.Height != (int)Info.Height || image.Format != Info.Format)
                throw new InvalidOperationException(string.Format(
                    "VrsyncCamera {0}: the frame's image is {1}x{2} {3}, the camera was set up for {4}x{5} {6}",
                    cameraName, image.Width, image.Height, image.Format, Info.Width, Info.Height, Info.Format));
            unityCamera.Render();
            Captures++;
            if (useReadPixels)
            {
                ReadPixelsInto(image);
                return;
            }
            Texture source = target;
            if (flipVertically)
            {
                Graphics.Blit(target, flipped, new Vector2(1, -1), new Vector2(0, 1));
                source = flipped;
            }
            // A NativeArray over the loaned frame: the readback's one copy lands in it.
            NativeArray<byte> destination = NativeArrayUnsafeUtility.ConvertExistingDataToNativeArray<byte>(
                (void*)image.Data, image.Length, Allocator.None);
#if ENABLE_UNITY_COLLECTIONS_CHECKS
            safety = AtomicSafetyHandle.Create();
            NativeArrayUnsafeUtility.SetAtomicSafetyHandle(ref destination, safety);
#endif
            request = AsyncGPUReadback.RequestIntoNativeArray(ref destination, source, 0, readFormat, null);
            pending = true;
            pendingImage = image;
            if (request.done && request.hasError)
                EndCapture();  // refused at once (format, platform): ReadPixels now
        }

        /// <summary>Whether the capture's readback has finished (true with none in flight).</summary>
        internal bool CaptureDone
        {
            get { return !pending || request.done; }
        }

        /// <summary>Blocks until the readback is done (sync mode, before publishing).</summary>
        internal void WaitForCapture()
        {
            if (pending && !request.done)
                request.WaitForCompletion();
        }

        /// <summary>
        /// Before publishing: waits for the readback if needed and ends it; a failed
        /// readback is replaced by ReadPixels (and this camera uses ReadPixels from then on).
        /// </summary>
        internal void EndCapture()
        {
            if (!pending)
                return;
            WaitForCapture();
            bool failed = request.hasError;
            pending = false;
            ReleaseSafety();
            if (failed)
            {
                if (!warnedFallback)
                {
                    Debug.LogWarning(string.Format(
                        "vrsync: AsyncGPUReadback of camera {0} into {1} failed; using ReadPixels for it from now on",
                        cameraName, readFormat));
                    warnedFallback = true;
                }
                useReadPixels = true;
                ReadPixelsInto(pendingImage);
            }
        }

        /// <summary>Waits for a readback in flight without publishing (shutdown: the memory
        /// it writes into must outlive it).</summary>
        internal void AbandonCapture()
        {
            if (!pending)
                return;
            WaitForCapture();
            pending = false;
            ReleaseSafety();
        }

        void ReleaseSafety()
        {
#if ENABLE_UNITY_COLLECTIONS_CHECKS
            AtomicSafetyHandle.Release(safety);
            safety = default(AtomicSafetyHandle);
#endif
        }

        /// <summary>The fallback: ReadPixels into a Texture2D (Unity's rows, bottom first),
        /// then its rows into <paramref name="image"/> in vrsync's order.</summary>
        unsafe void ReadPixelsInto(Image image)
        {
            int w = (int)Info.Width, h = (int)Info.Height;
            if (cpuCopy == null)
                cpuCopy = new Texture2D(w, h, readFormat, false);
            RenderTexture previous = RenderTexture.active;
            RenderTexture.active = target;
            cpuCopy.ReadPixels(new Rect(0, 0, w, h), 0, 0, false);
            RenderTexture.active = previous;
            NativeArray<byte> raw = cpuCopy.GetRawTextureData<byte>();
            var rows = new ReadOnlySpan<byte>(NativeArrayUnsafeUtility.GetUnsafeReadOnlyPtr(raw), raw.Length);
            if (flipVertically)
                image.CopyFromBottomUp(rows, image.Stride);
            else
                image.CopyFrom(rows.Slice(0, image.Length));
        }

        void ReleaseTextures()
        {
            if (unityCamera != null && unityCamera.targetTexture == target)
                unityCamera.targetTexture = null;
            if (target != null)
                Destroy(target);
            if (flipped != null)
                Destroy(flipped);
            if (cpuCopy != null)
                Destroy(cpuCopy);
            target = null;
            flipped = null;
            cpuCopy = null;
        }

        void OnDestroy()
        {
            AbandonCapture();
            ReleaseTextures();
        }
    }
}
