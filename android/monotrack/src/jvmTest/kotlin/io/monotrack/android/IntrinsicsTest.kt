package io.monotrack.android

import kotlin.math.abs
import org.junit.jupiter.api.Assertions.assertEquals
import org.junit.jupiter.api.Assertions.assertNull
import org.junit.jupiter.api.Assertions.assertTrue
import org.junit.jupiter.api.Test

class IntrinsicsTest {
    private fun near(a: Double, b: Double) = assertTrue(abs(a - b) < 1e-4, "$a vs $b")

    @Test
    fun calibrationIsScaledAndCroppedToTheBuffer() {
        // A 4000×3000 array delivered as 640×480: a uniform scale of 6.25, no crop.
        val k = CameraIntrinsicsMapping.fromCalibration(floatArrayOf(3000f, 3000f, 2010f, 1490f, 0f), 4000, 3000, 640, 480)!!
        near(k.fx, 480.0); near(k.fy, 480.0); near(k.cx, 321.6); near(k.cy, 238.4)
        // 16:9 from 4:3: rows cropped about the centre (3000 → 2250 rows, 375 cut at the top).
        val w = CameraIntrinsicsMapping.fromCalibration(floatArrayOf(3000f, 3000f, 2000f, 1500f), 4000, 3000, 1280, 720)!!
        near(w.fx, 960.0); near(w.cx, 640.0); near(w.cy, 360.0)
    }

    @Test
    fun missingOrBadValuesGiveNull() {
        assertNull(CameraIntrinsicsMapping.fromCalibration(null, 4000, 3000, 640, 480))
        assertNull(CameraIntrinsicsMapping.fromCalibration(floatArrayOf(1f, 1f, 1f), 4000, 3000, 640, 480))
        assertNull(CameraIntrinsicsMapping.fromCalibration(floatArrayOf(Float.NaN, 1f, 1f, 1f), 4000, 3000, 640, 480))
        assertNull(CameraIntrinsicsMapping.fromCalibration(floatArrayOf(1f, 1f, 1f, 1f), 0, 3000, 640, 480))
        assertNull(CameraIntrinsicsMapping.fromFocalLength(4.2f, null, 4.6f, 640, 480))
        assertNull(CameraIntrinsicsMapping.fromFieldOfView(180.0, 640, 480))
    }

    @Test
    fun focalLengthAndFieldOfViewGiveCentredIntrinsics() {
        // 4.8 mm lens on a 6.4×4.8 mm sensor at 640×480: 0.01 mm per pixel.
        val k = CameraIntrinsicsMapping.fromFocalLength(4.8f, 6.4f, 4.8f, 640, 480)!!
        near(k.fx, 480.0); near(k.cx, 320.0); near(k.cy, 240.0)
        val f = CameraIntrinsicsMapping.fromFieldOfView(90.0, 640, 480)!!
        near(f.fx, 320.0)
        assertEquals(f.fx, f.fy)
    }
}
