package io.monotrack.android

import android.graphics.Bitmap
import android.graphics.ImageFormat
import androidx.camera.core.ImageProxy
import io.monotrack.FrameDesc
import io.monotrack.MonotrackException
import java.nio.ByteBuffer
import java.nio.ByteOrder

/**
 * Pixel bytes together with the description that tells the SDK how to read them.
 *
 * @property bytes a direct buffer positioned at 0, holding the first pixel there. uniffi 0.32 passes a
 *   `&[u8]` argument as a borrowed direct `ByteBuffer` (no copy), valid for the call only.
 * @property desc the frame's layout, rotation and mirroring.
 */
public class Frame(public val bytes: ByteBuffer, public val desc: FrameDesc)

/**
 * The Y plane of this YUV_420_888 image as a GRAY8 [Frame], without copying: the returned buffer is
 * the plane's own (valid until the image is closed), `rowStride` is the plane's, and the rotation is
 * `imageInfo.rotationDegrees`.
 *
 * @param mirrored true for the front camera.
 * @throws MonotrackException.InvalidFrame when the image is not YUV_420_888, its plane buffer is not
 *   direct, or the plane is smaller than its stride says.
 */
public fun ImageProxy.lumaFrame(mirrored: Boolean): Frame {
    if (format != ImageFormat.YUV_420_888) {
        throw MonotrackException.InvalidFrame("ImageProxy format $format, expected YUV_420_888 (${ImageFormat.YUV_420_888})")
    }
    val y = planes[0]
    val buffer = y.buffer
    if (!buffer.isDirect) {
        throw MonotrackException.InvalidFrame("Y plane buffer is not direct")
    }
    // The native side reads from the buffer's base address; keep position and size in agreement.
    buffer.rewind()
    val desc = FrameMapping.lumaFrameDesc(
        width = width,
        height = height,
        yPlane = PlaneLayout(y.rowStride, y.pixelStride, buffer.remaining()),
        rotationDegrees = imageInfo.rotationDegrees,
        mirrored = mirrored,
    )
    return Frame(buffer, desc)
}

/**
 * Copies an `ARGB_8888` bitmap into a new direct buffer as an RGBA8 [Frame] (Android stores
 * ARGB_8888 pixels as R, G, B, A bytes). Meant for still images and the benchmark: it allocates.
 *
 * @throws MonotrackException.InvalidFrame when the bitmap is not ARGB_8888 or is recycled.
 */
public fun Bitmap.rgbaFrame(): Frame {
    if (isRecycled) throw MonotrackException.InvalidFrame("bitmap is recycled")
    if (config != Bitmap.Config.ARGB_8888) {
        throw MonotrackException.InvalidFrame("bitmap config $config, expected ARGB_8888")
    }
    val buffer = ByteBuffer.allocateDirect(rowBytes * height).order(ByteOrder.nativeOrder())
    copyPixelsToBuffer(buffer)
    buffer.rewind()
    val desc = FrameMapping.rgbaFrameDesc(width = width, height = height, rowStride = rowBytes, sizeBytes = buffer.remaining())
    return Frame(buffer, desc)
}
