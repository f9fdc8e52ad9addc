/**
 * @file slipest_features.h
 * @brief Streaming window feature extractor (integer sums only, no sample buffer).
 *
 * Push one raw telemetry sample at a time (7 int16 values in the raw CAN units of
 * RAW_CHANNELS: wheel_speed, motor_current, acc_x, acc_y, acc_z, roll, pitch) with its
 * acc_x/y/z are body-frame linear acceleration with gravity removed, as in the training
 * data (a raw accelerometer's specific force must have gravity subtracted first);
 * 16-bit sample counter. The window grid starts at the first accepted sample; a window
 * holds 100 counter slots. A window is emitted when its last slot is filled or when a
 * sample of a later window arrives; windows without any sample are skipped (counted as
 * flagged and dropped). The exact integer procedure is documented in
 * toolchain/data/features_int.py and mirrored here bit for bit.
 */
#ifndef SLIPEST_FEATURES_H
#define SLIPEST_FEATURES_H

#include <stddef.h>
#include <stdint.h>

#include "slipest_status.h"

#ifdef __cplusplus
extern "C" {
#endif

/** Raw telemetry channels per sample. */
#define SLIPEST_N_CHANNELS 7
/** Features per window (the model's inputs). */
#define SLIPEST_N_FEATURES 12
/** Counter slots per window. */
#define SLIPEST_SAMPLES_PER_WINDOW 100
/** Fewer samples than this make a window invalid (no estimate). */
#define SLIPEST_MIN_SAMPLES 5
/** Windows one push can close at most: the open window and a new one-sample window at its last slot. */
#define SLIPEST_MAX_CLOSED 2

/** Window flag: samples were missing. */
#define SLIPEST_FLAG_GAP 0x01u
/** Window flag: a value saturated (features or inference). */
#define SLIPEST_FLAG_SATURATION 0x02u
/** Window flag: fewer than SLIPEST_MIN_SAMPLES samples, no estimate. */
#define SLIPEST_FLAG_INVALID 0x04u
/** Window flag: features came in FEATURES frames, not from samples. */
#define SLIPEST_FLAG_FEATURES_INPUT 0x08u

/** One closed window: exact per-channel sums of the samples present. */
typedef struct {
    int32_t sum[SLIPEST_N_CHANNELS];   /**< |sum| <= 100 * 2^15 */
    int64_t sumsq[SLIPEST_N_CHANNELS]; /**< <= 100 * 2^30 */
    uint32_t index;                    /**< window index on the grid (window_counter = index & 0xFFFF) */
    uint8_t n;                         /**< samples present, 1..100 */
    uint8_t flags;                     /**< SLIPEST_FLAG_GAP / _INVALID */
} slipest_window_t;

/** Extractor state: the open window and the loss counters (no sample buffer). */
typedef struct {
    slipest_window_t open;      /**< window being accumulated (valid if has_open) */
    uint32_t slot;              /**< unwrapped slot of the last accepted sample */
    uint16_t last_counter;      /**< counter of the last accepted sample */
    uint8_t started;            /**< a first sample has been accepted since reset */
    uint8_t has_open;           /**< open window holds >= 1 sample */
    uint32_t samples_accepted;  /**< samples taken into windows */
    uint32_t samples_dropped;   /**< missing slots */
    uint32_t samples_rejected;  /**< late / duplicate samples */
    uint32_t windows_flagged;   /**< closed or skipped windows with n < 100 */
    uint32_t windows_closed;    /**< windows handed out */
} slipest_extractor_t;

/**
 * @brief Reset an extractor (grid and counters).
 * @param[out] ex  extractor state
 * @return SLIPEST_OK or SLIPEST_E_NULL
 */
slipest_status_t slipest_extractor_init(slipest_extractor_t *ex);

/**
 * @brief sizeof(slipest_extractor_t), for ctypes callers.
 * @return the size in bytes
 */
size_t slipest_extractor_size(void);

/**
 * @brief sizeof(slipest_window_t), for ctypes callers.
 * @return the size in bytes
 */
size_t slipest_window_size(void);

/**
 * @brief Restart the window grid at the next sample (counters are kept).
 * @param[in,out] ex  extractor state
 * @return SLIPEST_OK or SLIPEST_E_NULL
 */
slipest_status_t slipest_extractor_reset_grid(slipest_extractor_t *ex);

/**
 * @brief Push one sample.
 * @param[in,out] ex       extractor state
 * @param[in]     counter  16-bit sample counter
 * @param[in]     sample   the 7 raw channel values
 * @param[out]    out      receives the closed windows
 * @return the number of windows closed (0..SLIPEST_MAX_CLOSED), written to out[0..], SLIPEST_E_NULL,
 *         or SLIPEST_E_ORDER if the counter is not ahead of the last accepted one (16-bit delta 0
 *         or >= 32768; the sample is counted in samples_rejected and ignored)
 */
int slipest_extractor_push(slipest_extractor_t *ex, uint16_t counter,
                           const int16_t sample[SLIPEST_N_CHANNELS],
                           slipest_window_t out[SLIPEST_MAX_CLOSED]);

/**
 * @brief Check that a window's n and sums are consistent with int16 samples.
 * @param[in] w  window
 * @return SLIPEST_OK, SLIPEST_E_NULL or SLIPEST_E_RANGE
 */
slipest_status_t slipest_window_check(const slipest_window_t *w);

/**
 * @brief Integer features (int16, raw LSB units of each channel, FEATURE_NAMES order).
 * @param[in]  w     a closed window
 * @param[out] feat  receives the 12 features
 * @return the number of saturated values (>= 0) or a negative slipest_status_t
 */
int slipest_window_features_q(const slipest_window_t *w, int16_t feat[SLIPEST_N_FEATURES]);

/**
 * @brief Float features in physical units from the exact integer sums (float path).
 * @param[in]  w     a closed window
 * @param[out] feat  receives the 12 features
 * @return SLIPEST_OK or a negative slipest_status_t
 */
int slipest_window_features_f32(const slipest_window_t *w, float feat[SLIPEST_N_FEATURES]);

/**
 * @brief floor(sqrt(x)) exactly, for any uint64.
 * @param[in] x  the radicand
 * @return floor(sqrt(x))
 */
uint32_t slipest_isqrt_u64(uint64_t x);

#ifdef __cplusplus
}
#endif

#endif /* SLIPEST_FEATURES_H */
