package io.monotrack.bench

import io.monotrack.BenchReport
import io.monotrack.MonotrackException
import io.monotrack.StageStat
import org.junit.jupiter.api.Assertions.assertEquals
import org.junit.jupiter.api.Assertions.assertFalse
import org.junit.jupiter.api.Assertions.assertNull
import org.junit.jupiter.api.Assertions.assertTrue
import org.junit.jupiter.api.Test

class BenchSummaryTest {
    /** The 14 stages `run_benchmark` reports, with the totals given and every other stage at 1 ms. */
    private fun report(trackingTotalUs: Double, redetectTotalUs: Double, landmarksUs: Double = 1000.0): BenchReport {
        val names = listOf("image", "region", "detect", "landmarks", "flow", "fit", "total")
        val stages = listOf("tracking" to trackingTotalUs, "redetect" to redetectTotalUs).flatMap { (path, total) ->
            names.map { n ->
                val us = when (n) {
                    "total" -> total
                    "landmarks" -> landmarksUs
                    else -> 1000.0
                }
                StageStat("$path/$n", us, us * 1.5, us * 1.2)
            }
        }
        return BenchReport("android aarch64", 100u, if (landmarksUs > 0.0) 1u else 0u, 250_000.0, stages)
    }

    @Test
    fun tableHasAHeaderAndOneAlignedLinePerStageInMilliseconds() {
        val lines = BenchSummary.table(report(3380.0, 4080.0)).trimEnd().lines()
        assertEquals(15, lines.size)
        assertEquals("stage, ms            median      p90     mean", lines[0])
        assertEquals("tracking/total         3.38     5.07     4.06", lines[7])
        assertTrue(lines.all { it.length == lines[0].length }, lines.joinToString("\n"))
    }

    @Test
    fun totalsCompareTheMedianTotalsOfBothPaths() {
        val r = report(20_000.0, 500_000.0)
        val t = BenchSummary.totals(r)!!
        assertEquals(20.0, t.trackingMs, 1e-9)
        assertEquals(500.0, t.redetectMs, 1e-9)
        assertEquals(25.0, t.ratio!!, 1e-9)
        assertEquals(
            "per frame (median): tracking 20.00 ms, re-detect 500.00 ms, re-detect / tracking 25.00x",
            BenchSummary.totalsLine(r),
        )
        assertNull(PathTotals(0.0, 5.0).ratio)
        assertNull(BenchSummary.totals(BenchReport("x", 1u, 0u, 0.0, emptyList())))
    }

    @Test
    fun imageBlockWarnsWhenNoFaceWasFound() {
        val withFace = BenchSummary.imageBlock("astronaut.jpg", 512, 512, report(3000.0, 4000.0))
        assertTrue(withFace.startsWith("astronaut.jpg 512x512, 100 iterations per path, android aarch64, models loaded in 250.0 ms\n"), withFace)
        assertFalse(withFace.contains("no face"), withFace)
        val noFace = BenchSummary.imageBlock("blank.png", 64, 64, report(900.0, 900.0, landmarksUs = 0.0))
        assertTrue(noFace.contains("no face found"), noFace)
    }

    @Test
    fun thesisLineQuotesTheIphoneSeFigures() {
        assertEquals(
            "thesis, iPhone SE: tracking 19.6 ms, detection 525.6 ms per frame (26.8x)",
            BenchSummary.thesisLine(),
        )
    }

    @Test
    fun describeDropsUniffisMessagePrefix() {
        assertEquals("invalid frame: too short", BenchSummary.describe(MonotrackException.InvalidFrame("too short")))
        assertEquals("model load failed: bad bytes", BenchSummary.describe(MonotrackException.ModelLoad("bad bytes")))
    }
}
