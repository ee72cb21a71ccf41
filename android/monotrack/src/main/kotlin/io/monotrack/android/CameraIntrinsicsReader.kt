package io.monotrack.android

import android.hardware.camera2.CameraCharacteristics
import android.os.Build
import androidx.annotation.OptIn
import androidx.camera.camera2.interop.Camera2CameraInfo
import androidx.camera.camera2.interop.ExperimentalCamera2Interop
import androidx.camera.core.CameraInfo
import io.monotrack.CameraIntrinsics

/**
 * The intrinsics to put in `FaceTrackerOptions.camera` for this camera's [bufferWidth]×[bufferHeight]
 * frames as delivered (the analysis buffer's size, before rotation; the SDK turns and mirrors them
 * with each frame): `LENS_INTRINSIC_CALIBRATION` when the device reports it (API 28+), else the
 * lens's focal length over the sensor's physical size ([CameraIntrinsicsMapping]).
 *
 * @return null when the device reports neither; leave `camera` null then, and the SDK assumes its
 *   field-of-view default (about 58° across the longer side).
 */
@OptIn(ExperimentalCamera2Interop::class)
public fun CameraInfo.monotrackIntrinsics(bufferWidth: Int, bufferHeight: Int): CameraIntrinsics? {
    val info = Camera2CameraInfo.from(this)
    // Camera2 states the calibration in the pre-correction active array's pixels.
    val array = info.getCameraCharacteristic(CameraCharacteristics.SENSOR_INFO_PRE_CORRECTION_ACTIVE_ARRAY_SIZE)
        ?: info.getCameraCharacteristic(CameraCharacteristics.SENSOR_INFO_ACTIVE_ARRAY_SIZE)
    if (Build.VERSION.SDK_INT >= Build.VERSION_CODES.P && array != null) {
        val calibration = info.getCameraCharacteristic(CameraCharacteristics.LENS_INTRINSIC_CALIBRATION)
        CameraIntrinsicsMapping.fromCalibration(calibration, array.width(), array.height(), bufferWidth, bufferHeight)
            ?.let { return it }
    }
    val focal = info.getCameraCharacteristic(CameraCharacteristics.LENS_INFO_AVAILABLE_FOCAL_LENGTHS)?.firstOrNull()
    val sensor = info.getCameraCharacteristic(CameraCharacteristics.SENSOR_INFO_PHYSICAL_SIZE)
    return CameraIntrinsicsMapping.fromFocalLength(focal, sensor?.width, sensor?.height, bufferWidth, bufferHeight)
}
