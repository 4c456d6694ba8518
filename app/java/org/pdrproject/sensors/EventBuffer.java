package org.pdrproject.sensors;

import android.hardware.Sensor;
import android.hardware.SensorEvent;
import android.hardware.SensorEventListener;

/**
 * One sensor's events, kept in primitive arrays until Python takes them (app/sources.py, AndroidSource).
 *
 * A pyjnius listener costs Python a callback and two field reads through JNI per event (about 400 events a
 * second); this listener runs in Java on the sensor thread, and Python takes a poll's events with three calls:
 * take() moves them (oldest first) to the output arrays and says how many, takenTimes() and takenValues()
 * return those arrays. A full buffer drops its oldest event and counts it in dropped(), as the Python queue does.
 * Each event keeps width values: missing ones are NaN, further ones are not kept.
 */
public class EventBuffer implements SensorEventListener {
    private final int capacity;
    private final int width;
    private final long[] times;
    private final float[] values;
    private int start = 0;
    private int count = 0;
    private long dropped = 0;
    private volatile int accuracy = -2;  // -2: not reported yet (SENSOR_STATUS_* are -1..3)
    private long[] takenTimes = new long[0];
    private float[] takenValues = new float[0];

    public EventBuffer(int capacity, int width) {
        if (capacity < 1 || width < 1) {
            throw new IllegalArgumentException("capacity and width must be at least 1");
        }
        this.capacity = capacity;
        this.width = width;
        this.times = new long[capacity];
        this.values = new float[capacity * width];
    }

    @Override
    public void onSensorChanged(SensorEvent event) {
        float[] v = event.values;
        synchronized (this) {
            int slot;
            if (count < capacity) {
                slot = (start + count) % capacity;
                count++;
            } else {
                slot = start;  // overwrite the oldest
                start = (start + 1) % capacity;
                dropped++;
            }
            times[slot] = event.timestamp;
            int base = slot * width;
            for (int i = 0; i < width; i++) {
                values[base + i] = i < v.length ? v[i] : Float.NaN;
            }
        }
    }

    @Override
    public void onAccuracyChanged(Sensor sensor, int accuracy) {
        this.accuracy = accuracy;
    }

    /** Moves the buffered events to takenTimes() / takenValues() (oldest first); returns their number. */
    public synchronized int take() {
        long[] t = new long[count];
        float[] v = new float[count * width];
        for (int k = 0; k < count; k++) {
            int slot = (start + k) % capacity;
            t[k] = times[slot];
            System.arraycopy(values, slot * width, v, k * width, width);
        }
        start = 0;
        count = 0;
        takenTimes = t;
        takenValues = v;
        return t.length;
    }

    public synchronized long[] takenTimes() {
        return takenTimes;
    }

    public synchronized float[] takenValues() {
        return takenValues;
    }

    public synchronized long dropped() {
        return dropped;
    }

    public int accuracy() {
        return accuracy;
    }

    public int width() {
        return width;
    }
}
