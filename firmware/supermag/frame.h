/* SuperMag wire frame (docs/design.md, Wire protocol): encoder, CRC and the documented self-test pattern.
 *
 * Portable C99 with no Arduino or libc I/O dependency, so the sketch and the host tool `frame_dump`
 * compile the very same bytes. Little-endian on the wire whatever the CPU's byte order.
 *
 *   offset size field
 *        0    2 sync 0xAA 0x55
 *        2    1 version (1)
 *        3    1 flags: bit 0 = temperatures present
 *        4    2 seq u16, +1 per frame, wraps
 *        6    4 t_mcu_us u32, device clock in microseconds, wraps
 *       10    2 status u16: bit i set = chip i (row-major over the 4x4 grid) failed this frame
 *       12   96 B[16][3] int16 raw counts, axes x, y, z
 *      108   32 T[16] int16 chip temperatures in 0.01 degC (only when flags bit 0)
 *   -2        2 crc16 CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF) over every byte after the sync
 */
#ifndef SUPERMAG_FRAME_H
#define SUPERMAG_FRAME_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define SM_N_CHIPS 16
#define SM_VERSION 1
#define SM_FLAG_TEMPERATURE 0x01
#define SM_FRAME_LEN 110   /* without temperatures */
#define SM_FRAME_LEN_T 142 /* with temperatures */
#define SM_PERIOD_US 8000u /* 125 Hz */

typedef struct {
    uint16_t seq;
    uint32_t t_mcu_us;
    uint16_t status;                    /* bit i: chip i failed (no answer, or its ERROR status bit) */
    int16_t counts[SM_N_CHIPS][3];      /* raw counts, chip-major, axes x, y, z */
    int16_t temperature_cdeg[SM_N_CHIPS]; /* 0.01 degC; sent only when has_temperature */
    uint8_t has_temperature;
} sm_frame_t;

/* CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, no final xor); check("123456789") = 0x29B1. */
uint16_t sm_crc16(const uint8_t *data, size_t len);

/* Write one frame into out (capacity cap bytes); returns its length (110 or 142), or 0 when cap is too small. */
size_t sm_encode_frame(const sm_frame_t *frame, uint8_t *out, size_t cap);

/* The self-test pattern, frame k (what the firmware streams with SM_SELF_TEST, and frame_dump writes):
 *   seq      = k mod 2^16
 *   t_mcu_us = k * 8000 mod 2^32               (the 125 Hz schedule)
 *   counts[c][a] = (int16)((k * 97 + c * 1000 + a * 331) mod 2^16)   (two's complement: every sign, both rails)
 *   status   = (k mod 8 == 7) ? 1 << (k mod 16) : 0
 *   temperature_cdeg[c] = 2500 + 10 * c + (k mod 50), present when with_temperature != 0 */
void sm_self_test_frame(uint32_t k, int with_temperature, sm_frame_t *frame);

#ifdef __cplusplus
}
#endif

#endif /* SUPERMAG_FRAME_H */
