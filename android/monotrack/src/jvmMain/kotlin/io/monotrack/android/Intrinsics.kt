// Pure Kotlin (no android.* imports): camera intrinsics for the SDK from what Camera2 reports,
// unit-tested on the JVM. The SDK wants them for the buffer as delivered (before rotation and
// mirroring), in that buffer's pixels; it turns them with the frame itself.
package io.monotrack.android

import io.monotrack.CameraIntrinsics
import kotlin.math.tan

/** Derives the SDK's [CameraIntrinsics] from Camera2 characteristics. */
public object CameraIntrinsicsMapping {
    /** fx, fy, cx, cy (a fifth value, the skew, is ignored: zero on phone cameras). */
    private const val CALIBRATION_VALUES = 4

    /**
     * Intrinsics of a [bufferWidth]×[bufferHeight] output buffer from `LENS_INTRINSIC_CALIBRATION`
     * ([calibration]: fx, fy, cx, cy, skew in pixels of the [arrayWidth]×[arrayHeight] pre-correction
     * active array). The camera scales the array to the buffer, cropping the longer dimension to
     * the buffer's aspect ratio about the centre (the Camera2 default crop).
     *
     * @return null when [calibration] is missing, too short or not finite, or a size is not positive.
     */
    public fun fromCalibration(
        calibration: FloatArray?,
        arrayWidth: Int,
        arrayHeight: Int,
        bufferWidth: Int,
        bufferHeight: Int,
    ): CameraIntrinsics? {
        if (calibration == null || calibration.size < CALIBRATION_VALUES) return null
        if (arrayWidth <= 0 || arrayHeight <= 0 || bufferWidth <= 0 || bufferHeight <= 0) return null
        val (fx, fy, cx, cy) = calibration.take(CALIBRATION_VALUES).map { it.toDouble() }
        if (listOf(fx, fy, cx, cy).any { !it.isFinite() } || fx <= 0 || fy <= 0) return null
        // The centred crop of the array with the buffer's aspect ratio, then a uniform scale.
        val scale = minOf(arrayWidth.toDouble() / bufferWidth, arrayHeight.toDouble() / bufferHeight)
        val cropX = (arrayWidth - bufferWidth * scale) / 2
        val cropY = (arrayHeight - bufferHeight * scale) / 2
        return CameraIntrinsics(fx = fx / scale, fy = fy / scale, cx = (cx - cropX) / scale, cy = (cy - cropY) / scale)
    }

    /**
     * Intrinsics from the lens's focal length and the sensor's physical size when the device gives no
     * calibration: `LENS_INFO_AVAILABLE_FOCAL_LENGTHS` ([focalLengthMm]) and
     * `SENSOR_INFO_PHYSICAL_SIZE` ([sensorWidthMm]×[sensorHeightMm], the pixel array's size), centred
     * principal point, with the same centred crop as [fromCalibration].
     *
     * @return null when a value is missing or not positive (then pass no intrinsics: the SDK's
     *   field-of-view default applies).
     */
    public fun fromFocalLength(
        focalLengthMm: Float?,
        sensorWidthMm: Float?,
        sensorHeightMm: Float?,
        bufferWidth: Int,
        bufferHeight: Int,
    ): CameraIntrinsics? {
        if (focalLengthMm == null || sensorWidthMm == null || sensorHeightMm == null) return null
        if (!(focalLengthMm > 0 && sensorWidthMm > 0 && sensorHeightMm > 0)) return null
        if (bufferWidth <= 0 || bufferHeight <= 0) return null
        // Millimetres per buffer pixel after the centred crop.
        val mmPerPixel = minOf(sensorWidthMm.toDouble() / bufferWidth, sensorHeightMm.toDouble() / bufferHeight)
        val f = focalLengthMm / mmPerPixel
        return CameraIntrinsics(fx = f, fy = f, cx = bufferWidth / 2.0, cy = bufferHeight / 2.0)
    }

    /** Intrinsics for a horizontal field of view of [horizontalFovDegrees] across the buffer's width. */
    public fun fromFieldOfView(horizontalFovDegrees: Double, bufferWidth: Int, bufferHeight: Int): CameraIntrinsics? {
        if (!(horizontalFovDegrees > 0 && horizontalFovDegrees < 180) || bufferWidth <= 0 || bufferHeight <= 0) return null
        val f = bufferWidth / 2.0 / tan(Math.toRadians(horizontalFovDegrees) / 2)
        return CameraIntrinsics(fx = f, fy = f, cx = bufferWidth / 2.0, cy = bufferHeight / 2.0)
    }
}
