package dev.waymark;

import dev.waymark.android.Platform;
import dev.waymark.android.WaymarkJava;
import dev.waymark.android.WaymarkLocationCallback;
import dev.waymark.android.WaymarkLocationClient;
import dev.waymark.android.WaymarkLocationRequest;
import dev.waymark.android.WaymarkLocationStatus;
import dev.waymark.android.WaymarkPermission;
import dev.waymark.android.WaymarkPermissions;
import java.util.ArrayList;
import java.util.Arrays;
import java.util.List;

/**
 * The Android client from Java, compiled by javac against the Kotlin classes
 * (bindings/kotlin/test.sh): a builder for the request, a callback that overrides only what it
 * needs (the others are default methods), no unsigned type anywhere. AndroidClientTest runs it.
 */
public final class JavaCaller {
    private JavaCaller() {}

    public static String run(PositioningEngineInterface engine, Platform platform, RadioScan scan) {
        WaymarkLocationRequest defaults = new WaymarkLocationRequest();
        WaymarkLocationRequest request = WaymarkLocationRequest.builder().setSensorRateHz(50).setAdvanceIntervalMs(1_000).build();
        if (request.getSensorRateHz() != 50 || !defaults.getWifi()) return "builder: " + request;
        try {
            WaymarkLocationRequest.builder().setWifi(false).setBle(false).build();
            return "a request with no radio was built";
        } catch (IllegalArgumentException expected) {
            // as the constructor
        }
        String[] names = WaymarkPermissions.manifestNames(WaymarkPermissions.foreground(34));
        if (!Arrays.asList(names).contains("android.permission.ACCESS_COARSE_LOCATION")) return "permissions: " + Arrays.toString(names);

        ((FakeAvailability) platform.getAvailability()).getGranted().remove(WaymarkPermission.BLUETOOTH_SCAN);
        final List<Integer> codes = new ArrayList<>();
        final List<Long> times = new ArrayList<>();
        WaymarkLocationCallback callback = new WaymarkLocationCallback() {
            @Override
            public void onLocation(PositionEstimate position) {
                times.add(WaymarkJava.timestampNanos(position));
            }

            @Override
            public void onStatus(WaymarkLocationStatus status) {
                if (status instanceof WaymarkLocationStatus.PermissionMissing) codes.add(status.getCode());
            }
        };
        WaymarkLocationClient client = new WaymarkLocationClient(engine, platform);
        client.requestLocationUpdates(request, Runnable::run, callback);
        PositionEstimate position = engine.pushScan(scan);
        long t = WaymarkJava.timestampNanos(position);
        int floor = WaymarkJava.floorIndex(position);
        MotionSample sample = WaymarkJava.motionSample(t, 0.0, 0.0, 9.81);
        client.close();
        if (!times.contains(t)) return "positions: " + times + " without " + t;
        if (sample.getZ() != 9.81 || floor < 0) return "sample " + sample + ", floor " + floor;
        return "ok statuses=" + codes + " position=" + t + " floor=" + floor;
    }
}
