package io.monotrack.bench

import android.graphics.Bitmap
import android.graphics.BitmapFactory
import android.os.Build
import android.os.Bundle
import android.os.Handler
import android.os.Looper
import android.widget.Button
import android.widget.TextView
import androidx.appcompat.app.AppCompatActivity
import io.monotrack.MonotrackException
import io.monotrack.android.rgbaFrame
import io.monotrack.android.toTable
import io.monotrack.runBenchmark
import io.monotrack.sdkVersion
import java.util.concurrent.Executors

/**
 * Runs `runBenchmark` (per-stage median and p90 over tracked and re-detect frames, the same code as
 * the desktop bench) on every bundled image and prints one table per image, like the thesis'
 * Tables 4.4/4.5. Runs on a background thread; results are selectable text to copy into reports.
 */
class BenchActivity : AppCompatActivity() {
    private val worker = Executors.newSingleThreadExecutor()
    private val main = Handler(Looper.getMainLooper())
    private lateinit var report: TextView
    private lateinit var run: Button

    override fun onCreate(savedInstanceState: Bundle?) {
        super.onCreate(savedInstanceState)
        setContentView(R.layout.activity_bench)
        report = findViewById(R.id.report)
        run = findViewById(R.id.run)
        run.setOnClickListener { start() }
    }

    private fun start() {
        run.isEnabled = false
        report.setText(R.string.running)
        worker.execute {
            val text = try {
                benchmarkAll()
            } catch (e: MonotrackException) {
                "benchmark failed: ${e.message}"
            }
            main.post {
                report.text = text
                run.isEnabled = true
            }
        }
    }

    private fun benchmarkAll(): String {
        val sb = StringBuilder()
        sb.append("monotrack ${sdkVersion()} on ${Build.MANUFACTURER} ${Build.MODEL} (${Build.SUPPORTED_ABIS.first()}, API ${Build.VERSION.SDK_INT})\n\n")
        val images = assets.list("").orEmpty().filter { name -> IMAGE_EXTENSIONS.any { name.lowercase().endsWith(it) } }.sorted()
        for (name in images) {
            val bitmap = assets.open(name).use {
                BitmapFactory.decodeStream(it, null, BitmapFactory.Options().apply { inPreferredConfig = Bitmap.Config.ARGB_8888 })
            } ?: continue
            val frame = bitmap.rgbaFrame()
            bitmap.recycle()
            val r = runBenchmark(frame.bytes, frame.desc, ITERATIONS)
            sb.append("$name ${frame.desc.width}x${frame.desc.height}, ${r.iterations} iterations (${r.device})\n")
            sb.append(r.toTable()).append('\n')
        }
        if (images.isEmpty()) sb.append("no bundled images\n")
        return sb.toString()
    }

    override fun onDestroy() {
        super.onDestroy()
        worker.shutdownNow()
    }

    private companion object {
        /** Tracked frames per image: enough for a stable p90 (≥ 10 samples above it) in a few seconds. */
        const val ITERATIONS = 200u
        val IMAGE_EXTENSIONS = listOf(".jpg", ".jpeg", ".png")
    }
}
