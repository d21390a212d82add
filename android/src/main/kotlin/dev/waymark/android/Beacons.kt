package dev.waymark.android

import dev.waymark.BeaconReading

/** An iBeacon advertisement's identity and calibrated power. */
data class IBeacon(val uuid: String, val major: Int, val minor: Int, val txPowerDbm: Int)

/**
 * An Eddystone-UID frame's identity: [namespace] (10 bytes, 20 lower-case hex digits) and
 * [instance] (6 bytes, 12 hex digits), and its calibrated power at 0 m. The identity is the
 * beacon's own; the advertiser's MAC address is not (many beacons rotate it).
 */
data class EddystoneUid(val namespace: String, val instance: String, val txPowerDbm: Int) {
    /** The identity as Waymark keys it: the 16 bytes, namespace then instance, written as a
     *  UUID (8-4-4-4-12 hex digits: the namespace fills the first four groups, the instance
     *  the last), with major and minor 0 and no address. */
    val uuid: String
        get() = "${namespace.substring(0, 8)}-${namespace.substring(8, 12)}-${namespace.substring(12, 16)}-" +
            "${namespace.substring(16, 20)}-$instance"
}

/**
 * BLE advertisements as Waymark beacons, in plain Kotlin. An iBeacon is Apple manufacturer
 * data (company id 0x004C) holding type 0x02, length 0x15, the proximity UUID (16 bytes),
 * major and minor (big-endian) and the measured power at 1 m (signed); an Eddystone beacon
 * advertises service data for the 16-bit UUID 0xFEAA (Bluetooth SIG assigned numbers; Apple's
 * "Proximity Beacon Specification" for iBeacon).
 */
object BleAdvertisements {
    const val APPLE_COMPANY_ID = 0x004C
    const val EDDYSTONE_SERVICE_UUID = 0xFEAA
    private const val IBEACON_TYPE = 0x02
    private const val IBEACON_LENGTH = 0x15
    private const val AD_MANUFACTURER_DATA = 0xFF
    private const val AD_SERVICE_DATA_16 = 0x16
    private const val EDDYSTONE_UID_FRAME = 0x00

    /** Frame type, ranging power, namespace (10) and instance (6). */
    private const val EDDYSTONE_UID_LENGTH = 18

    /** The iBeacon in manufacturer data [data] (after the company id), or null if it is none. */
    fun iBeacon(companyId: Int, data: ByteArray): IBeacon? {
        if (companyId != APPLE_COMPANY_ID || data.size < 2 + IBEACON_LENGTH) return null
        if (u8(data, 0) != IBEACON_TYPE || u8(data, 1) != IBEACON_LENGTH) return null
        val hex = (2 until 18).joinToString("") { "%02x".format(u8(data, it)) }
        val uuid = "${hex.substring(0, 8)}-${hex.substring(8, 12)}-${hex.substring(12, 16)}-" +
            "${hex.substring(16, 20)}-${hex.substring(20)}"
        return IBeacon(uuid, u16(data, 18), u16(data, 20), data[22].toInt())
    }

    /** The iBeacon in a raw advertisement (`ScanRecord.getBytes()`), or null. */
    fun iBeacon(record: ByteArray): IBeacon? {
        var found: IBeacon? = null
        structures(record) { type, start, end ->
            if (found == null && type == AD_MANUFACTURER_DATA && end - start >= 2) {
                found = iBeacon(u8(record, start) or (u8(record, start + 1) shl 8), record.copyOfRange(start + 2, end))
            }
        }
        return found
    }

    /** The Eddystone-UID frame in a raw advertisement, or null: service data for 0xFEAA with
     *  frame type 0x00, the ranging power, the namespace and the instance (Google's
     *  Eddystone-UID specification; the two reserved bytes after them are optional). */
    fun eddystoneUid(record: ByteArray): EddystoneUid? {
        var found: EddystoneUid? = null
        structures(record) { type, start, end ->
            if (found == null && type == AD_SERVICE_DATA_16 && end - start >= 2 + EDDYSTONE_UID_LENGTH &&
                (u8(record, start) or (u8(record, start + 1) shl 8)) == EDDYSTONE_SERVICE_UUID &&
                u8(record, start + 2) == EDDYSTONE_UID_FRAME
            ) {
                val hex = { from: Int, to: Int -> (from until to).joinToString("") { "%02x".format(u8(record, it)) } }
                found = EddystoneUid(hex(start + 4, start + 14), hex(start + 14, start + 20), record[start + 3].toInt())
            }
        }
        return found
    }

    /** Whether a raw advertisement carries Eddystone service data (any frame). */
    fun isEddystone(record: ByteArray): Boolean {
        var found = false
        structures(record) { type, start, end ->
            if (type == AD_SERVICE_DATA_16 && end - start >= 2 &&
                (u8(record, start) or (u8(record, start + 1) shl 8)) == EDDYSTONE_SERVICE_UUID
            ) {
                found = true
            }
        }
        return found
    }

    /**
     * The reading Waymark takes for an advertisement, without RSSI and age; null when it is
     * neither an iBeacon nor an Eddystone-UID frame (a phone, headphones, Eddystone's URL, TLM
     * and EID frames: none names a transmitter of the site). An iBeacon is keyed by UUID, major
     * and minor (by [address] at the factory's major = minor = 0); an Eddystone beacon by its
     * namespace and instance ([EddystoneUid.uuid]), never by its rotating address.
     */
    fun reading(address: String, record: ByteArray?): BeaconReading? {
        record ?: return null
        iBeacon(record)?.let {
            return BeaconReading(uuid = it.uuid, major = it.major.toUShort(), minor = it.minor.toUShort(), rssiDbm = 0.0, address = address)
        }
        eddystoneUid(record)?.let { return BeaconReading(uuid = it.uuid, rssiDbm = 0.0, address = null) }
        return null
    }

    /** Calls [each] with every AD structure's type and data range; stops at a malformed one. */
    private inline fun structures(record: ByteArray, each: (type: Int, start: Int, end: Int) -> Unit) {
        var i = 0
        while (i < record.size) {
            val length = u8(record, i)
            if (length == 0 || i + 1 + length > record.size) return
            each(u8(record, i + 1), i + 2, i + 1 + length)
            i += 1 + length
        }
    }

    private fun u8(b: ByteArray, i: Int): Int = b[i].toInt() and 0xFF

    private fun u16(b: ByteArray, i: Int): Int = (u8(b, i) shl 8) or u8(b, i + 1)
}

/**
 * Beacon advertisements heard between epochs, each beacon's RSSI averaged over the
 * advertisements of one epoch (a beacon advertises several times a second; one reading is
 * noisy by several dB).
 */
internal class BeaconWindow(private val capacity: Int = 4_096) {
    private class Heard(val key: BeaconReading, val rssiDbm: Int, val timestampNs: Long)

    private val heard = ArrayDeque<Heard>()

    val isEmpty: Boolean get() = heard.isEmpty()

    fun add(key: BeaconReading, rssiDbm: Int, timestampNs: Long) {
        if (heard.size == capacity) heard.removeFirst()
        heard.addLast(Heard(key, rssiDbm, timestampNs))
    }

    /** Takes out what was heard at or before [atNs], one reading per beacon, its age the time
     *  since its newest advertisement; what was heard later stays for the next epoch. */
    fun drain(atNs: Long, maxAgeNs: Long): List<BeaconReading> {
        val taken = heard.filter { it.timestampNs <= atNs }
        heard.removeAll { it.timestampNs <= atNs }
        return taken.filter { atNs - it.timestampNs <= maxAgeNs }.groupBy { it.key }.map { (key, all) ->
            val newestNs = all.maxOf { it.timestampNs }
            key.copy(rssiDbm = all.map { it.rssiDbm }.average(), ageMs = ((atNs - newestNs) / 1_000_000L).toULong())
        }
    }

    fun clear() = heard.clear()
}
