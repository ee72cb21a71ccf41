// JVM tests of motion comparison through the generated bindings: a recorded trial and the same
// frames fed live to a MotionSession score alike and blame the faulty joint; bad input is typed.
package io.monotrack.tests

import io.monotrack.BodyJoint
import io.monotrack.BodyJoint3d
import io.monotrack.MonotrackException
import io.monotrack.MotionFeature
import io.monotrack.MotionFrame
import io.monotrack.MotionSession
import io.monotrack.Vec3
import io.monotrack.compareMotion
import kotlin.math.PI
import kotlin.math.cos
import kotlin.math.sin
import org.junit.jupiter.api.Assertions.assertEquals
import org.junit.jupiter.api.Assertions.assertThrows
import org.junit.jupiter.api.Assertions.assertTrue
import org.junit.jupiter.api.Test

private val WEIGHTS = """{"phases": [{"name": "swing", "start_frame": 0, "end_frame": 39}],
  "features": [{"phase": "swing", "joint": "relbow", "feature": "flexion", "weight": 1},
               {"phase": "swing", "joint": "rwrist", "feature": "linear_velocity", "weight": 1}]}"""

/** A right-arm swing frame (phase 0..1), the elbow bent [bend] degrees more. */
private fun frame(phase: Double, bend: Double): MotionFrame {
    val th = Math.toRadians(50.0 * sin(2 * PI * phase))
    val el = Math.toRadians(30.0 + 25.0 * cos(2 * PI * phase) + bend)
    val sh = Vec3(-180.0, 0.0, 1380.0)
    val elbow = Vec3(sh.x, sh.y + 290 * sin(th), sh.z - 290 * cos(th))
    val wrist = Vec3(elbow.x, elbow.y + 250 * sin(th + el), elbow.z - 250 * cos(th + el))
    val pos = mapOf(
        BodyJoint.PELVIS to Vec3(0.0, 0.0, 900.0), BodyJoint.THORAX to Vec3(0.0, 0.0, 1400.0),
        BodyJoint.L_SHOULDER to Vec3(180.0, 0.0, 1380.0), BodyJoint.L_ELBOW to Vec3(200.0, 0.0, 1100.0),
        BodyJoint.L_WRIST to Vec3(210.0, 60.0, 860.0), BodyJoint.R_SHOULDER to sh, BodyJoint.R_ELBOW to elbow,
        BodyJoint.R_WRIST to wrist, BodyJoint.L_HIP to Vec3(100.0, 0.0, 900.0), BodyJoint.L_KNEE to Vec3(100.0, 30.0, 480.0),
        BodyJoint.L_ANKLE to Vec3(100.0, 0.0, 80.0), BodyJoint.R_HIP to Vec3(-100.0, 0.0, 900.0),
        BodyJoint.R_KNEE to Vec3(-100.0, 0.0, 480.0), BodyJoint.R_ANKLE to Vec3(-100.0, 0.0, 80.0),
        BodyJoint.HEAD to Vec3(0.0, 20.0, 1620.0),
    )
    return MotionFrame(pos.map { (j, p) -> BodyJoint3d(j, p) })
}

private fun sequence(n: Int, bend: Double) = (0 until n).map { frame(it.toDouble() / (n - 1), bend) }

class MotionTest {
    @Test
    fun aRecordedAndALiveTrialScoreAlikeAndBlameTheElbow() {
        val reference = sequence(40, 0.0)
        val trial = sequence(44, 25.0)
        val report = compareMotion(reference, trial, WEIGHTS, 30.0)
        assertTrue(report.overall < 0.95, "overall ${report.overall}")
        assertEquals(BodyJoint.R_ELBOW, report.worst.joint)
        assertEquals(MotionFeature.FLEXION, report.worst.feature)
        assertTrue(report.summary.contains("right elbow"), report.summary)
        assertEquals(0u, report.path.first().referenceFrame)
        MotionSession(reference, WEIGHTS, 30.0).use { live ->
            trial.forEach { live.addFrame(it) }
            assertEquals(report, live.finish())
            assertThrows(MonotrackException.InvalidFrame::class.java) { live.finish() }
        }
        val same = compareMotion(reference, reference, WEIGHTS, 30.0)
        assertEquals(1.0, same.overall, 1e-9)
    }

    @Test
    fun badInputIsTyped() {
        val reference = sequence(40, 0.0)
        assertThrows(MonotrackException.InvalidConfig::class.java) {
            compareMotion(reference, reference, WEIGHTS.replace("flexion", "twist"), 30.0)
        }
        assertThrows(MonotrackException.InvalidConfig::class.java) {
            MotionSession(reference.take(20), WEIGHTS, 30.0)
        }
        val missing = MotionFrame(reference[0].joints.drop(1))
        assertThrows(MonotrackException.InvalidConfig::class.java) {
            compareMotion(reference, listOf(missing) + reference, WEIGHTS, 30.0)
        }
    }
}
