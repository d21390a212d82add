package dev.waymark

import java.io.File

/** One epoch of `walk.json` (from `waymark sim-export`), already in FFI form. */
class Epoch(
    val timestampNs: ULong,
    val truthX: Double,
    val truthY: Double,
    val accelerometer: List<MotionSample>,
    val gyroscope: List<MotionSample>,
    val magnetometer: List<MotionSample>,
    val wifi: List<WifiReading>,
) {
    fun scan(): RadioScan = RadioScan(timestampNs, wifi, emptyList())
}

/** A surveyor's tap: at (x, y) m at [timestampNs]. */
class Tap(val timestampNs: ULong, val x: Double, val y: Double)

/** A survey walk of `survey/walk-K.json` (from `waymark sim-export`): its epochs and taps. */
class SurveyWalk(val name: String, val epochs: List<Epoch>, val taps: List<Tap>)

/** Reads the walk exported by `waymark sim-export` (JVM has no JSON library: [MiniJson]). */
object Walk {
    fun load(path: String): List<Epoch> = epochs(MiniJson(File(path).readText()).parse() as Map<*, *>)

    /** A survey walk, with the waypoints the surveyor taps. */
    fun loadSurvey(file: File): SurveyWalk {
        val root = MiniJson(file.readText()).parse() as Map<*, *>
        val taps = (root["waypoints"] as List<*>).map { w ->
            val v = w as List<*>
            Tap((v[0] as Double).toLong().toULong(), v[1] as Double, v[2] as Double)
        }
        return SurveyWalk(file.nameWithoutExtension, epochs(root), taps)
    }

    private fun epochs(root: Map<*, *>): List<Epoch> {
        return (root["epochs"] as List<*>).map { e ->
            e as Map<*, *>
            val truth = e["truth"] as List<*>
            Epoch(
                timestampNs = (e["timestamp_ns"] as Double).toLong().toULong(),
                truthX = truth[0] as Double,
                truthY = truth[1] as Double,
                accelerometer = samples(e["accelerometer"]),
                gyroscope = samples(e["gyroscope"]),
                magnetometer = samples(e["magnetometer"]),
                wifi = (e["wifi"] as List<*>).map { w ->
                    w as Map<*, *>
                    WifiReading(w["bssid"] as String, w["rssi_dbm"] as Double, 0uL)
                },
            )
        }
    }

    private fun samples(rows: Any?): List<MotionSample> = (rows as List<*>).map { r ->
        val v = r as List<*>
        MotionSample((v[0] as Double).toLong().toULong(), v[1] as Double, v[2] as Double, v[3] as Double)
    }
}

/**
 * A minimal JSON reader: objects -> Map, arrays -> List, numbers -> Double, strings, booleans,
 * null. Enough for `walk.json`; numbers up to 2^53 (nanosecond timestamps) are exact.
 */
class MiniJson(private val s: String) {
    private var i = 0

    fun parse(): Any? {
        val v = value()
        ws()
        require(i == s.length) { "trailing text at $i" }
        return v
    }

    private fun ws() {
        while (i < s.length && s[i].isWhitespace()) i++
    }

    private fun expect(c: Char) {
        ws()
        require(i < s.length && s[i] == c) { "expected '$c' at $i" }
        i++
    }

    private fun value(): Any? {
        ws()
        require(i < s.length) { "unexpected end" }
        return when (val c = s[i]) {
            '{' -> obj()
            '[' -> arr()
            '"' -> str()
            't' -> literal("true", true)
            'f' -> literal("false", false)
            'n' -> literal("null", null)
            else -> if (c == '-' || c.isDigit()) num() else throw IllegalArgumentException("bad char '$c' at $i")
        }
    }

    private fun literal(word: String, v: Any?): Any? {
        require(s.startsWith(word, i)) { "expected $word at $i" }
        i += word.length
        return v
    }

    private fun obj(): Map<String, Any?> {
        expect('{')
        val m = LinkedHashMap<String, Any?>()
        ws()
        if (s[i] == '}') { i++; return m }
        while (true) {
            ws()
            val k = str()
            expect(':')
            m[k] = value()
            ws()
            if (s[i] == ',') { i++; continue }
            expect('}')
            return m
        }
    }

    private fun arr(): List<Any?> {
        expect('[')
        val l = ArrayList<Any?>()
        ws()
        if (s[i] == ']') { i++; return l }
        while (true) {
            l.add(value())
            ws()
            if (s[i] == ',') { i++; continue }
            expect(']')
            return l
        }
    }

    private fun str(): String {
        expect('"')
        val b = StringBuilder()
        while (true) {
            val c = s[i++]
            when (c) {
                '"' -> return b.toString()
                '\\' -> {
                    when (val e = s[i++]) {
                        'n' -> b.append('\n'); 't' -> b.append('\t'); 'r' -> b.append('\r')
                        'b' -> b.append('\b'); 'f' -> b.append('\u000C')
                        'u' -> { b.append(s.substring(i, i + 4).toInt(16).toChar()); i += 4 }
                        else -> b.append(e)
                    }
                }
                else -> b.append(c)
            }
        }
    }

    private fun num(): Double {
        val start = i
        while (i < s.length && (s[i].isDigit() || s[i] in "+-.eE")) i++
        return s.substring(start, i).toDouble()
    }
}
