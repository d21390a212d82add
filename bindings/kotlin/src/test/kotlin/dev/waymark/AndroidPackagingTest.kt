package dev.waymark

import dev.waymark.android.WaymarkPermission
import dev.waymark.android.WaymarkPermissions
import java.io.File
import javax.xml.parsers.DocumentBuilderFactory
import org.junit.Assert.assertEquals
import org.junit.Assert.assertTrue
import org.junit.Test

/**
 * What the AAR build would package, checked without Gradle (which cannot run here): the R8
 * rules keep classes that exist in the generated bindings, the build pins a JNA that works
 * with 16 KB pages and links the native library for them, and the manifest declares what
 * [WaymarkPermissions] asks the app to request, and nothing for the background.
 */
class AndroidPackagingTest {
    private val android = File(System.getProperty("waymark.android"))
    private val guide = File(android.parentFile, "docs/android.md").readText()
    private val build = File(android, "build.gradle.kts").readText()

    @Test
    fun theConsumerRulesKeepJnaAndClassesThatExist() {
        assertTrue(build.contains("consumerProguardFiles(\"consumer-rules.pro\")"))
        val rules = File(android, "consumer-rules.pro").readLines().map { it.trim() }.filter { it.isNotEmpty() && !it.startsWith("#") }
        assertTrue(rules.toString(), "-keep class com.sun.jna.** { *; }" in rules)
        assertTrue(rules.toString(), "-keepclassmembers class * extends com.sun.jna.** { public *; }" in rules)
        // Every class the rules name is one the bindings have; the JNA supertypes they name exist.
        val named = rules.flatMap { Regex("""class (dev\.waymark\.[A-Za-z]+|com\.sun\.jna\.[A-Za-z]+)\b""").findAll(it).map { m -> m.groupValues[1] }.toList() }
        assertTrue(named.toString(), named.size >= 2)
        for (name in named) Class.forName(name, false, javaClass.classLoader)
        for (supertype in rules.flatMap { Regex("""(?:extends|implements) (com\.sun\.jna\.[A-Za-z]+)""").findAll(it).map { m -> m.groupValues[1] }.toList() }) {
            Class.forName(supertype, false, javaClass.classLoader)
        }
        // The bindings do bind native methods and Structures, which the rules are for.
        val lib = Class.forName("dev.waymark.UniffiLib", false, javaClass.classLoader)
        assertTrue(lib.declaredMethods.any { java.lang.reflect.Modifier.isNative(it.modifiers) })
        assertTrue(com.sun.jna.Structure::class.java.isAssignableFrom(Class.forName("dev.waymark.RustBuffer", false, javaClass.classLoader)))
    }

    @Test
    fun theBuildPinsA16KbJnaLinksFor16KbPagesAndPublishes() {
        val jna = Regex("""api\("net\.java\.dev\.jna:jna:(\d+)\.(\d+)\.(\d+)@aar"\)""").find(build)
        assertTrue("JNA is an api dependency as @aar", jna != null)
        val (major, minor) = jna!!.destructured
        // 5.16.0 fixed JNA's calls on 16 KB pages, 5.17.0 the alignment of its libraries.
        assertTrue("JNA ${jna.value}", major.toInt() > 5 || (major.toInt() == 5 && minor.toInt() >= 17))
        assertTrue("the guide names the same JNA", guide.contains(jna.value.substringAfter("api(\"").substringBefore("\")")))
        assertTrue(build.contains("api(\"org.jetbrains.kotlinx:kotlinx-coroutines-core:"))
        assertTrue(build.contains("-Wl,-z,max-page-size=16384"))
        assertTrue("the host's library, not a hard-coded .so", build.contains("libwaymark.dylib") && build.contains("\$hostLibrary"))
        assertTrue(build.contains("`maven-publish`") && Regex("""version = "\d+\.\d+\.\d+"""").containsMatchIn(build))
        val version = Regex("""version = "(\d+\.\d+\.\d+)"""").find(build)!!.groupValues[1]
        assertTrue("the guide's coordinates", guide.contains("dev.waymark:waymark-android:$version"))
        assertTrue(guide.contains("gradle publishToMavenLocal"))
    }

    @Test
    fun theManifestDeclaresWhatTheAppIsAskedToRequest() {
        val doc = DocumentBuilderFactory.newInstance().apply { isNamespaceAware = true }
            .newDocumentBuilder().parse(File(android, "src/main/AndroidManifest.xml"))
        val ns = "http://schemas.android.com/apk/res/android"
        val nodes = doc.getElementsByTagName("uses-permission")
        val declared = (0 until nodes.length).map { (nodes.item(it) as org.w3c.dom.Element).getAttributeNS(ns, "name") }.toSet()
        // Everything any Android version asks for in the foreground is declared.
        for (sdk in 24..35) for (p in WaymarkPermissions.foreground(sdk)) assertTrue("$sdk: ${p.manifestName}", p.manifestName in declared)
        // The background is the app's choice: neither background location nor a location
        // foreground service comes with the AAR.
        for (p in listOf(WaymarkPermission.ACCESS_BACKGROUND_LOCATION, WaymarkPermission.FOREGROUND_SERVICE_LOCATION)) {
            assertTrue(p.manifestName, p.manifestName !in declared)
        }
        assertEquals(0, doc.getElementsByTagName("service").length)
        // The app's part is in the guide, for the service the AAR has.
        assertTrue(guide.contains("android:name=\"dev.waymark.android.WaymarkForegroundService\""))
        assertTrue(guide.contains("android:foregroundServiceType=\"location\""))
        assertTrue(File(android, "src/main/kotlin/dev/waymark/android/WaymarkForegroundService.kt").readText().contains("class WaymarkForegroundService : Service()"))
    }
}
