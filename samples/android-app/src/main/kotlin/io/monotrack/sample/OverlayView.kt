package io.monotrack.sample

import android.content.Context
import android.graphics.Canvas
import android.graphics.Color
import android.graphics.Paint
import android.util.AttributeSet
import android.view.View
import io.monotrack.TrackingResult
import io.monotrack.android.LANDMARK_COUNT
import io.monotrack.android.ViewMapping
import io.monotrack.android.axes
import io.monotrack.android.brows
import io.monotrack.android.copyLandmarksTo
import io.monotrack.android.gazeArrows
import io.monotrack.android.mouth
import java.util.Locale

/**
 * Draws a [TrackingResult] over a FILL_CENTER camera preview: landmarks, head axes (x red, y green,
 * z blue), gaze arrows, the most probable mouth and brow gestures, and the frame rate.
 * Paints and the point array are allocated once; [onDraw] allocates only the gesture strings.
 */
class OverlayView @JvmOverloads constructor(context: Context, attrs: AttributeSet? = null) : View(context, attrs) {
    private var result: TrackingResult? = null
    private var fps = 0.0
    private val points = FloatArray(2 * LANDMARK_COUNT)

    private val pointPaint = Paint(Paint.ANTI_ALIAS_FLAG).apply {
        color = Color.CYAN
        strokeWidth = 6f
        strokeCap = Paint.Cap.ROUND
    }
    private val axisPaints = listOf(Color.RED, Color.GREEN, Color.BLUE).map { c ->
        Paint(Paint.ANTI_ALIAS_FLAG).apply {
            color = c
            strokeWidth = 8f
        }
    }
    private val gazePaint = Paint(Paint.ANTI_ALIAS_FLAG).apply {
        color = Color.YELLOW
        strokeWidth = 5f
    }
    private val textPaint = Paint(Paint.ANTI_ALIAS_FLAG).apply {
        color = Color.WHITE
        textSize = 44f
        setShadowLayer(4f, 0f, 0f, Color.BLACK)
    }

    /** Shows [result] (call on the UI thread). */
    fun show(result: TrackingResult, fps: Double) {
        this.result = result
        this.fps = fps
        invalidate()
    }

    override fun onDraw(canvas: Canvas) {
        super.onDraw(canvas)
        val r = result ?: return
        canvas.drawText(String.format(Locale.ROOT, "%.1f fps  %.1f ms", fps, r.timings.totalUs.toDouble() / US_PER_MS), 24f, 60f, textPaint)
        if (r.frameWidth == 0u || r.frameHeight == 0u || width == 0 || height == 0) return
        val w = r.frameWidth.toInt()
        val h = r.frameHeight.toInt()
        val m = ViewMapping.centered(w, h, width, height, fill = true)
        // The intrinsics the tracker used for this upright image.
        val camera = r.camera

        for (face in r.faces) {
            val n = face.copyLandmarksTo(points)
            m.mapPoints(points, n)
            canvas.drawPoints(points, 0, n, pointPaint)

            face.pose.axes(camera, AXIS_LENGTH_MM)?.let { a ->
                val ox = m.x(a.origin.x)
                val oy = m.y(a.origin.y)
                listOf(a.x, a.y, a.z).forEachIndexed { i, tip ->
                    canvas.drawLine(ox, oy, m.x(tip.x), m.y(tip.y), axisPaints[i])
                }
            }
            face.gazeArrows(GAZE_ARROW_PX)?.let { arrows ->
                for (a in listOf(arrows.right, arrows.left)) {
                    canvas.drawLine(m.x(a.from.x), m.y(a.from.y), m.x(a.to.x), m.y(a.to.y), gazePaint)
                }
            }
            val label = face.gestures?.let { g ->
                val (mouth, pm) = g.mouth()
                val (brows, pb) = g.brows()
                String.format(Locale.ROOT, "%s %.2f  brows %s %.2f  yaw %.0f°", mouth, pm, brows, pb, face.pose.yawDeg)
            } ?: String.format(Locale.ROOT, "yaw %.0f°", face.pose.yawDeg)
            canvas.drawText(label, m.x(face.bbox.x), m.y(face.bbox.y) - TEXT_GAP_PX, textPaint)
        }
    }

    private companion object {
        /** Axis length: about half a face width, so the gizmo stays inside the head. */
        const val AXIS_LENGTH_MM = 70.0

        /** Gaze arrow length in result-image pixels: visible at 640x480 without covering the face. */
        const val GAZE_ARROW_PX = 60f
        const val TEXT_GAP_PX = 12f
        const val US_PER_MS = 1000.0
    }
}
