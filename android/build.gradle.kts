// The Waymark Android library (AAR). Built on a developer's machine with the Android SDK/NDK,
// Gradle and cargo-ndk (see README.md and docs/android.md#building-the-aar); CI here has
// neither, so it tests the Kotlin on the JVM (bindings/kotlin/test.sh).
plugins {
    id("com.android.library") version "8.7.0"
    id("org.jetbrains.kotlin.android") version "2.0.21"
    `maven-publish`
}

group = "dev.waymark"
version = "0.1.0"

android {
    namespace = "dev.waymark"
    compileSdk = 35
    defaultConfig {
        minSdk = 24
        // Applied to the app's R8 run: JNA's keep rules and the bindings' (consumer-rules.pro).
        consumerProguardFiles("consumer-rules.pro")
    }
    sourceSets["main"].java.srcDir(layout.buildDirectory.dir("generated/uniffi"))
    compileOptions {
        sourceCompatibility = JavaVersion.VERSION_17
        targetCompatibility = JavaVersion.VERSION_17
    }
    publishing {
        singleVariant("release") {
            withSourcesJar()
        }
    }
}

kotlin {
    jvmToolchain(17)
    // Interface methods with a body become Java default methods: a Java WaymarkLocationCallback
    // overrides only onLocation.
    compilerOptions { freeCompilerArgs.add("-Xjvm-default=all") }
}

dependencies {
    // `api`: the app gets both with the AAR from a Maven repository (they are in its POM).
    // JNA as @aar carries JNA's own native library for every ABI; 5.15.0 and later are built
    // for 16 KB memory pages, which Google Play requires of apps targeting Android 15+.
    api("net.java.dev.jna:jna:5.17.0@aar")
    // The client's Flow (locations, locationEvents).
    api("org.jetbrains.kotlinx:kotlinx-coroutines-core:1.8.1")
}

val repo = rootDir.parentFile

// Native libraries for every ABI, into src/main/jniLibs. `-z max-page-size=16384` aligns the
// ELF segments to 16 KB, which phones with 16 KB pages (and Google Play, for apps targeting
// Android 15+) need; NDK r27 and earlier link with 4 KB by default.
val cargoNdk by tasks.registering(Exec::class) {
    workingDir = repo
    environment("RUSTFLAGS", "-C link-arg=-Wl,-z,max-page-size=16384")
    commandLine("cargo", "ndk", "-t", "arm64-v8a", "-t", "armeabi-v7a", "-t", "x86_64",
        "-o", "android/src/main/jniLibs", "build", "--release", "-p", "waymark", "--lib")
}

// Kotlin bindings generated from the host build of the library (glean's approach): the host's
// dynamic library is libwaymark.dylib on macOS, libwaymark.so on Linux.
val generateBindings by tasks.registering(Exec::class) {
    workingDir = repo
    val out = layout.buildDirectory.dir("generated/uniffi").get().asFile
    val hostLibrary = if (System.getProperty("os.name").lowercase().contains("mac")) "libwaymark.dylib" else "libwaymark.so"
    commandLine("bash", "-c",
        "cargo build -p uniffi-bindgen && cargo build -p waymark --lib && " +
        "target/debug/uniffi-bindgen generate --no-format --library target/debug/$hostLibrary " +
        "--language kotlin --out-dir ${out.absolutePath}")
}

tasks.named("preBuild") { dependsOn(cargoNdk, generateBindings) }

// `gradle publishToMavenLocal` (~/.m2/repository), or `gradle publish` into build/repo, a
// directory Maven repository to copy or serve: dev.waymark:waymark-android:0.1.0 (AAR + POM
// with JNA and coroutines as dependencies). docs/android.md#publishing.
publishing {
    publications {
        register<MavenPublication>("release") {
            groupId = "dev.waymark"
            artifactId = "waymark-android"
            version = project.version.toString()
            afterEvaluate { from(components["release"]) }
            pom {
                name.set("Waymark for Android")
                description.set("Indoor positioning from WiFi, BLE and motion: the engine, its Kotlin bindings and WaymarkLocationClient.")
            }
        }
    }
    repositories {
        maven {
            name = "local"
            url = uri(layout.buildDirectory.dir("repo"))
        }
    }
}
