// Stubs of Unity.Collections.NativeArray<T>, Allocator and
// Unity.Collections.LowLevel.Unsafe.NativeArrayUnsafeUtility / AtomicSafetyHandle (see
// UnityEngine.cs for what these stubs are). A NativeArray here is a pointer and a length;
// the safety handle, which exists when ENABLE_UNITY_COLLECTIONS_CHECKS is defined (the
// editor), is counted so tests can see that every handle created is released.

using System;
using System.Runtime.InteropServices;
using Unity.Collections.LowLevel.Unsafe;

namespace Unity.Collections
{
    public enum Allocator
    {
        Invalid = 0,
        None = 1,
        Temp = 2,
        TempJob = 3,
        Persistent = 4,
    }

    public unsafe struct NativeArray<T> : IDisposable where T : struct
    {
        internal void* m_Buffer;
        internal int m_Length;
        internal Allocator m_AllocatorLabel;
#if ENABLE_UNITY_COLLECTIONS_CHECKS
        internal AtomicSafetyHandle m_Safety;
#endif

        public int Length { get { return m_Length; } }
        public bool IsCreated { get { return m_Buffer != null; } }

        public T this[int index]
        {
            get
            {
                if ((uint)index >= (uint)m_Length)
                    throw new IndexOutOfRangeException();
                return (T)Marshal.PtrToStructure((IntPtr)((byte*)m_Buffer + (long)index * Marshal.SizeOf(typeof(T))), typeof(T));
            }
        }

        public void Dispose()
        {
            if (m_AllocatorLabel == Allocator.None || m_AllocatorLabel == Allocator.Invalid)
                throw new InvalidOperationException(
                    "The NativeArray can not be Disposed because it was not allocated with a valid allocator.");
            m_Buffer = null;
        }
    }
}

namespace Unity.Collections.LowLevel.Unsafe
{
    public struct AtomicSafetyHandle
    {
        internal int id;

        /// <summary>Stub only: handles created and not yet released.</summary>
        public static int StubLive;
        static int next;

        public static AtomicSafetyHandle Create()
        {
            StubLive++;
            return new AtomicSafetyHandle { id = ++next };
        }

        public static void Release(AtomicSafetyHandle handle)
        {
            if (handle.id == 0)
                throw new InvalidOperationException("stub: releasing a handle that was never created");
            StubLive--;
        }
    }

    public static unsafe class NativeArrayUnsafeUtility
    {
        public static NativeArray<T> ConvertExistingDataToNativeArray<T>(void* dataPointer, int length, Allocator allocator)
            where T : struct
        {
            if (length < 0)
                throw new ArgumentOutOfRangeException("length");
            return new NativeArray<T> { m_Buffer = dataPointer, m_Length = length, m_AllocatorLabel = allocator };
        }

        public static void* GetUnsafePtr<T>(this NativeArray<T> nativeArray) where T : struct
        {
            return nativeArray.m_Buffer;
        }

        public static void* GetUnsafeReadOnlyPtr<T>(this NativeArray<T> nativeArray) where T : struct
        {
            return nativeArray.m_Buffer;
        }

#if ENABLE_UNITY_COLLECTIONS_CHECKS
        public static void SetAtomicSafetyHandle<T>(ref NativeArray<T> array, AtomicSafetyHandle safety) where T : struct
        {
            array.m_Safety = safety;
        }

        public static AtomicSafetyHandle GetAtomicSafetyHandle<T>(NativeArray<T> array) where T : struct
        {
            return array.m_Safety;
        }
#endif
    }
}
