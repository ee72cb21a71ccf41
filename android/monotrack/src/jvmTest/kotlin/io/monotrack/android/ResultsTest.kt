package io.monotrack.android

import io.monotrack.BenchReport
import io.monotrack.CameraIntrinsics
import io.monotrack.Face
import io.monotrack.FaceState
import io.monotrack.Gaze
import io.monotrack.Gestures
import io.monotrack.HeadPose
import io.monotrack.MonotrackException
import io.monotrack.Point2
import io.monotrack.Rect
import io.monotrack.StageStat
import io.monotrack.Vec3
import io.monotrack.PointOfGaze
import io.monotrack.GazeSource
import io.monotrack.ShapeUnits
import io.monotrack.ActionUnits
import io.monotrack.EyeOpenness
import io.monotrack.FaceQuality
import io.monotrack.PoseUncertainty
import org.junit.jupiter.api.Assertions.assertEquals
import org.junit.jupiter.api.Assertions.assertNotNull
import org.junit.jupiter.api.Assertions.assertNull
import org.junit.jupiter.api.Assertions.assertThrows
import org.junit.jupiter.api.Test

private const val EPS = 1e-4f

private val IDENTITY = listOf(1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)

private fun pose(rotation: List<Double>, t: Vec3) =
    HeadPose(rotation = rotation, translationMm = t, yawDeg = 0.0, pitchDeg = 0.0, rollDeg = 0.0)

private fun face(landmarks: List<Point2>, gaze: Gaze) = Face(
    id = 1uL,
    state = FaceState.TRACKED,
    bbox = Rect(x = 0f, y = 0f, width = 100f, height = 100f),
    score = 0.9f,
    landmarks = landmarks,
    landmarkConfidence = null,
    eyes = EyeOpenness(leftOpen = 0.9f, rightOpen = 0.8f),
    gestures = Gestures(0.7f, 0.1f, 0.2f, 0.2f, 0.3f, 0.5f),
    gaze = gaze,
    pose = pose(IDENTITY, Vec3(0.0, 0.0, 500.0)),
    uncertainty = PoseUncertainty(1.0, 1.0, 1.0, Vec3(1.0, 1.0, 5.0)),
    quality = FaceQuality(0.9f, emptyList()),
    transform = null,
    shapeUnits = ShapeUnits(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
    actionUnits = ActionUnits(0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
    pointOfGaze = PointOfGaze(Vec3(0.0, 0.0, 500.0), Vec3(0.0, 0.0, -1.0), GazeSource.EYES, 1.0, 0.0, null),
    verticesMm = emptyList(),
)

class ResultsTest {
    @Test
    fun frontalPoseAxesProjectAlongImageAxes() {
        // The native headAxes, through the extension.
        val k = CameraIntrinsics(fx = 500.0, fy = 500.0, cx = 320.0, cy = 240.0)
        val axes = pose(IDENTITY, Vec3(10.0, -20.0, 500.0)).axes(k, 50.0)
        assertNotNull(axes)
        axes!!
        assertEquals(330f, axes.origin.x, EPS)
        assertEquals(220f, axes.origin.y, EPS)
        // x: 60 mm at 500 mm -> 60 px right of the centre; y: 30 mm -> 30 px down; z: straight away
        assertEquals(380f, axes.x.x, EPS)
        assertEquals(220f, axes.x.y, EPS)
        assertEquals(330f, axes.y.x, EPS)
        assertEquals(270f, axes.y.y, EPS)
        assertEquals(320f + 10f * 500f / 550f, axes.z.x, EPS)
        // 90° yaw about y: head x maps to camera -z, behind the camera when the head is near.
        val ry90 = listOf(0.0, 0.0, 1.0, 0.0, 1.0, 0.0, -1.0, 0.0, 0.0)
        assertNull(pose(ry90, Vec3(0.0, 0.0, 40.0)).axes(k, 50.0))
        assertThrows(MonotrackException.InvalidConfig::class.java) {
            pose(listOf(1.0, 0.0), Vec3(0.0, 0.0, 1.0)).axes(k, 50.0)
        }
    }

    @Test
    fun gazeArrowsStartAtEyeCentroids() {
        val lm = List(68) { i ->
            when (i) {
                in 36..41 -> Point2(x = 100f + (i - 36), y = 50f)
                in 42..47 -> Point2(x = 200f, y = 60f + (i - 42))
                else -> Point2(x = 0f, y = 0f)
            }
        }
        val g = Gaze(left = Vec3(0.0, 1.0, 0.0), right = Vec3(-0.6, 0.0, 0.8), combined = Vec3(0.0, 0.0, 1.0))
        val arrows = face(lm, g).gazeArrows(20f)!!
        val (r, l) = arrows.right to arrows.left
        assertEquals(102.5f, r.from.x, EPS)
        assertEquals(50f, r.from.y, EPS)
        assertEquals(102.5f - 12f, r.to.x, EPS)
        assertEquals(62.5f, l.from.y, EPS)
        assertEquals(82.5f, l.to.y, EPS)
        assertNull(face(lm, g).copy(gaze = null).gazeArrows(20f))
        assertThrows(MonotrackException.InvalidConfig::class.java) { face(lm.take(10), g).gazeArrows(20f) }
    }

    @Test
    fun landmarksCopyAndViewMappingCompose() {
        val lm = List(68) { i -> Point2(x = i.toFloat(), y = 2f * i) }
        val out = FloatArray(2 * 68)
        val n = face(lm, Gaze(Vec3(0.0, 0.0, 1.0), Vec3(0.0, 0.0, 1.0), Vec3(0.0, 0.0, 1.0))).copyLandmarksTo(out)
        assertEquals(136, n)
        // 480x640 image filling a 1080x1920 view: scale 3 (height-bound), 180 px cropped each side.
        val m = ViewMapping.centered(480, 640, 1080, 1920, fill = true)
        assertEquals(3f, m.scale, EPS)
        assertEquals(-180f, m.offsetX, EPS)
        m.mapPoints(out, n)
        assertEquals(-180f + 3f * 67f, out[134], EPS)
        assertEquals(3f * 134f, out[135], EPS)
        val fit = ViewMapping.centered(480, 640, 1080, 1920, fill = false)
        assertEquals(2.25f, fit.scale, EPS)
        assertEquals(240f, fit.offsetY, EPS)
        assertThrows(IllegalArgumentException::class.java) { ViewMapping.centered(0, 1, 1, 1, true) }
        assertThrows(IllegalArgumentException::class.java) { face(lm, Gaze(Vec3(0.0, 0.0, 1.0), Vec3(0.0, 0.0, 1.0), Vec3(0.0, 0.0, 1.0))).copyLandmarksTo(FloatArray(3)) }
    }

    @Test
    fun gestureLabelsPickTheMostProbable() {
        val g = Gestures(smile = 0.1f, kiss = 0.6f, mouthNeutral = 0.3f, browRaise = 0.5f, browFrown = 0.1f, browNeutral = 0.4f)
        assertEquals("kiss" to 0.6f, g.mouth())
        assertEquals("raise" to 0.5f, g.brows())
    }

    @Test
    fun benchTableListsStagesInMilliseconds() {
        val r = BenchReport(
            device = "test",
            iterations = 10u,
            faces = 1u,
            modelLoadUs = 0.0,
            stages = listOf(StageStat("landmarks", 1234.0, 2000.0, 1300.0), StageStat("fit", 500.0, 750.0, 520.0)),
        )
        val lines = r.toTable().trimEnd().lines()
        assertEquals(3, lines.size)
        assertEquals(listOf("stage", "median", "ms", "p90", "ms"), lines[0].split(Regex(" +")))
        assertEquals(listOf("landmarks", "1.23", "2.00"), lines[1].split(Regex(" +")))
        assertEquals(listOf("fit", "0.50", "0.75"), lines[2].split(Regex(" +")))
    }
}
