// JVM tests of point of gaze through the generated bindings: targets from JSON and a phone
// screen, each face's point of gaze, a tap calibration, typed errors.
package io.monotrack.tests

import io.monotrack.FaceTracker
import io.monotrack.FrameDesc
import io.monotrack.GazeTarget
import io.monotrack.MonotrackException
import io.monotrack.PixelFormat
import io.monotrack.PlanePoint
import io.monotrack.Vec3
import io.monotrack.FaceTrackerOptions
import io.monotrack.RunningMode
import io.monotrack.gazeTargetsFromJson
import io.monotrack.screenTarget
import java.io.File
import java.nio.ByteBuffer
import javax.imageio.ImageIO
import kotlin.math.hypot
import org.junit.jupiter.api.Assertions.assertEquals
import org.junit.jupiter.api.Assertions.assertNull
import org.junit.jupiter.api.Assertions.assertThrows
import org.junit.jupiter.api.Assertions.assertTrue
import org.junit.jupiter.api.Test

private val base = File(System.getProperty("monotrack.root") ?: ".")

class GazeTest {
    private fun face(): Pair<ByteBuffer, FrameDesc> {
        val img = ImageIO.read(File(base, "samples/data/astronaut.jpg"))
        val (w, h) = img.width to img.height
        val buf = ByteBuffer.allocateDirect(w * h)
        for (y in 0 until h) for (x in 0 until w) {
            val p = img.getRGB(x, y)
            buf.put(((77 * ((p shr 16) and 0xff) + 150 * ((p shr 8) and 0xff) + 29 * (p and 0xff) + 128) shr 8).toByte())
        }
        buf.rewind()
        return buf to FrameDesc(w.toUInt(), h.toUInt(), PixelFormat.GRAY8, w.toUInt(), 0u, 0u, 0u, false)
    }

    @Test
    fun theDriverZonesParseAndBadTargetsAreTypedErrors() {
        val zones = gazeTargetsFromJson(File(base, "examples/driver_zones.json").readText())
        assertEquals(
            listOf("left_window", "left_mirror", "road", "navigation", "rear_mirror", "right_mirror", "right_window"),
            zones.map { it.id },
        )
        assertThrows(MonotrackException.InvalidConfig::class.java) { gazeTargetsFromJson("{\"targets\": []}") }
        assertThrows(MonotrackException.InvalidConfig::class.java) { screenTarget("s", -1.0, 100.0, 0.0, 0.0) }
        FaceTracker(FaceTrackerOptions(runningMode = RunningMode.VIDEO)).use { t ->
            val line = GazeTarget("line", listOf(Vec3(0.0, 0.0, 0.0), Vec3(1.0, 0.0, 0.0), Vec3(2.0, 0.0, 0.0)))
            assertThrows(MonotrackException.InvalidConfig::class.java) { t.setGazeTargets(listOf(line)) }
        }
    }

    @Test
    fun facesCarryAPointOfGazeAndATapCalibratesIt() {
        val (buf, desc) = face()
        FaceTracker(FaceTrackerOptions(runningMode = RunningMode.VIDEO)).use { t ->
            t.setGazeTargets(listOf(screenTarget("phone", 70.0, 150.0, 35.0, -8.0)))
            val first = t.detectForVideo(buf, desc, 10L).faces.single().pointOfGaze!!
            assertTrue(first.originMm.z in 200.0..3000.0, "origin ${first.originMm}")
            assertEquals("phone", first.target!!.nearest)
            assertThrows(MonotrackException.InvalidFrame::class.java) {
                t.addCalibrationPoint("phone", PlanePoint(10.0, 10.0), 5_000L)
            }
            assertEquals(1u, t.addCalibrationPoint("phone", PlanePoint(20.0, 90.0), 11L))
            val hit = t.detectForVideo(buf, desc, 43L).faces.single().pointOfGaze!!.target!!
            assertTrue(hit.hit && hypot(hit.point.uMm - 20.0, hit.point.vMm - 90.0) < 10.0, "landed at ${hit.point}")
            t.setGazeTargets(emptyList())
            assertNull(t.detectForVideo(buf, desc, 76L).faces.single().pointOfGaze!!.target)
        }
    }
}
