// Pure Kotlin (no android.* imports) so it compiles and is unit-tested on a plain JVM; see
// android/README.md "JVM tests".
package io.monotrack.android

import io.monotrack.FrameDesc
import io.monotrack.MonotrackException
import io.monotrack.PixelFormat
import io.monotrack.frameByteCount

/**
 * The layout of one image plane as a camera API reports it, free of Android types so that the
 * mapping to [FrameDesc] can be tested on the JVM.
 *
 * @property rowStride bytes from the start of one row to the start of the next.
 * @property pixelStride bytes from one pixel to the next in a row (1 for a YUV_420_888 Y plane).
 * @property sizeBytes bytes readable in the plane's buffer (`ByteBuffer.remaining()`).
 */
public data class PlaneLayout(val rowStride: Int, val pixelStride: Int, val sizeBytes: Int)

/**
 * Maps camera buffers to the SDK's [FrameDesc] without copying pixels: the description tells the
 * core how to read the caller's bytes in place.
 */
public object FrameMapping {
    /** Bytes per pixel of [PixelFormat.RGBA8] (Android `Bitmap.Config.ARGB_8888` stores R, G, B, A). */
    public const val RGBA_BYTES_PER_PIXEL: Int = 4

    /** A quarter turn: CameraX and AVFoundation report rotations in multiples of it. */
    private const val QUARTER_TURN_DEG = 90
    private const val FULL_TURN_DEG = 360

    /**
     * Normalises a clockwise rotation in degrees to 0, 90, 180 or 270 (CameraX's
     * `ImageInfo.rotationDegrees` is already one of these; display rotations may be negative or ≥ 360).
     *
     * @throws MonotrackException.InvalidFrame when [degrees] is not a multiple of 90.
     */
    public fun normalizeRotation(degrees: Int): Int {
        if (degrees % QUARTER_TURN_DEG != 0) {
            throw MonotrackException.InvalidFrame("rotation $degrees° is not a multiple of 90°")
        }
        return ((degrees % FULL_TURN_DEG) + FULL_TURN_DEG) % FULL_TURN_DEG
    }

    /**
     * Describes the luma (Y) plane of a YUV_420_888 image as a [PixelFormat.GRAY8] frame: the core
     * tracks on luma only, so plane 0 is passed as is and the chroma planes are never touched.
     *
     * @param width image width in pixels (of the buffer, before rotation).
     * @param height image height in pixels (of the buffer, before rotation).
     * @param yPlane plane 0's layout.
     * @param rotationDegrees clockwise rotation that makes the buffer upright (CameraX `rotationDegrees`).
     * @param mirrored true for a front camera, so that results come out as the user sees the preview.
     * @throws MonotrackException.InvalidFrame when the sizes, strides or buffer length are inconsistent.
     */
    public fun lumaFrameDesc(
        width: Int,
        height: Int,
        yPlane: PlaneLayout,
        rotationDegrees: Int,
        mirrored: Boolean,
    ): FrameDesc {
        if (yPlane.pixelStride != 1) {
            // YUV_420_888 guarantees pixelStride 1 for Y; anything else is not a GRAY8 layout.
            throw MonotrackException.InvalidFrame("Y plane pixelStride ${yPlane.pixelStride}, expected 1")
        }
        return checked(FrameDesc(
            width = width.toUInt(),
            height = height.toUInt(),
            format = PixelFormat.GRAY8,
            rowStride = yPlane.rowStride.toUInt(),
            uvRowStride = 0u,
            uvPixelStride = 0u,
            rotationDegrees = normalizeRotation(rotationDegrees).toUInt(),
            mirrored = mirrored,
        ), yPlane.sizeBytes, "Y plane")
    }

    /**
     * Describes a packed RGBA frame (a decoded `Bitmap` copied with `copyPixelsToBuffer`).
     *
     * @param rowStride bytes per row (`Bitmap.rowBytes`); `width * 4` when tightly packed.
     * @param sizeBytes bytes available in the buffer.
     * @throws MonotrackException.InvalidFrame when the sizes, stride or buffer length are inconsistent.
     */
    public fun rgbaFrameDesc(
        width: Int,
        height: Int,
        rowStride: Int = width * RGBA_BYTES_PER_PIXEL,
        sizeBytes: Int,
        rotationDegrees: Int = 0,
        mirrored: Boolean = false,
    ): FrameDesc {
        return checked(FrameDesc(
            width = width.toUInt(),
            height = height.toUInt(),
            format = PixelFormat.RGBA8,
            rowStride = rowStride.toUInt(),
            uvRowStride = 0u,
            uvPixelStride = 0u,
            rotationDegrees = normalizeRotation(rotationDegrees).toUInt(),
            mirrored = mirrored,
        ), sizeBytes, "RGBA buffer")
    }

    /** [desc] when a buffer of [sizeBytes] holds it (the native `frameByteCount` says what it needs). */
    private fun checked(desc: FrameDesc, sizeBytes: Int, what: String): FrameDesc {
        val need = frameByteCount(desc)
        if (sizeBytes < 0 || sizeBytes.toULong() < need) {
            throw MonotrackException.InvalidFrame(
                "$what holds $sizeBytes bytes, ${desc.width}x${desc.height} with rowStride ${desc.rowStride} needs $need",
            )
        }
        return desc
    }
}
