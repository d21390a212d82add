// The Waymark Android library (AAR). Built on a developer's machine with the Android SDK/NDK,
// Gradle and cargo-ndk (see README.md); CI here has neither, so it tests the Kotlin on the JVM.
plugins {
    id("com.android.library") version "8.7.0"
    id("org.jetbrains.kotlin.android") version "2.0.21"
}

android {
    namespace = "dev.waymark"
    compileSdk = 35
    defaultConfig { minSdk = 24 }
    sourceSets["main"].java.srcDir(layout.buildDirectory.dir("generated/uniffi"))
}

dependencies {
    implementation("net.java.dev.jna:jna:5.14.0@aar")
    implementation("org.jetbrains.kotlinx:kotlinx-coroutines-core:1.8.1")
}

val repo = rootDir.parentFile

// Native libraries for every ABI, into src/main/jniLibs.
val cargoNdk by tasks.registering(Exec::class) {
    workingDir = repo
    commandLine("cargo", "ndk", "-t", "arm64-v8a", "-t", "armeabi-v7a", "-t", "x86_64",
        "-o", "android/src/main/jniLibs", "build", "--release", "-p", "waymark", "--lib")
}

// Kotlin bindings generated from the host build of the library (glean's approach).
val generateBindings by tasks.registering(Exec::class) {
    workingDir = repo
    val out = layout.buildDirectory.dir("generated/uniffi").get().asFile
    commandLine("bash", "-c",
        "cargo build -p uniffi-bindgen && cargo build -p waymark --lib && " +
        "target/debug/uniffi-bindgen generate --no-format --library target/debug/libwaymark.so " +
        "--language kotlin --out-dir ${out.absolutePath}")
}

tasks.named("preBuild") { dependsOn(cargoNdk, generateBindings) }
