/* SuperMag wire frame encoder and CRC (see frame.h for the layout). */
#include "frame.h"

uint16_t sm_crc16(const uint8_t *data, size_t len)
{
    uint16_t crc = 0xFFFF;
    for (size_t i = 0; i < len; ++i) {
        crc ^= (uint16_t)data[i] << 8;
        for (int bit = 0; bit < 8; ++bit) {
            crc = (crc & 0x8000) ? (uint16_t)((crc << 1) ^ 0x1021) : (uint16_t)(crc << 1);
        }
    }
    return crc;
}

static uint8_t *put_u16(uint8_t *p, uint16_t v)
{
    p[0] = (uint8_t)(v & 0xFF);
    p[1] = (uint8_t)(v >> 8);
    return p + 2;
}

static uint8_t *put_u32(uint8_t *p, uint32_t v)
{
    p = put_u16(p, (uint16_t)(v & 0xFFFF));
    return put_u16(p, (uint16_t)(v >> 16));
}

size_t sm_encode_frame(const sm_frame_t *frame, uint8_t *out, size_t cap)
{
    size_t len = frame->has_temperature ? SM_FRAME_LEN_T : SM_FRAME_LEN;
    if (cap < len) {
        return 0;
    }
    uint8_t *p = out;
    *p++ = 0xAA;
    *p++ = 0x55;
    *p++ = SM_VERSION;
    *p++ = frame->has_temperature ? SM_FLAG_TEMPERATURE : 0;
    p = put_u16(p, frame->seq);
    p = put_u32(p, frame->t_mcu_us);
    p = put_u16(p, frame->status);
    for (int c = 0; c < SM_N_CHIPS; ++c) {
        for (int a = 0; a < 3; ++a) {
            p = put_u16(p, (uint16_t)frame->counts[c][a]);
        }
    }
    if (frame->has_temperature) {
        for (int c = 0; c < SM_N_CHIPS; ++c) {
            p = put_u16(p, (uint16_t)frame->temperature_cdeg[c]);
        }
    }
    /* the CRC covers everything after the two sync bytes */
    put_u16(p, sm_crc16(out + 2, (size_t)(p - out) - 2));
    return len;
}

void sm_self_test_frame(uint32_t k, int with_temperature, sm_frame_t *frame)
{
    frame->seq = (uint16_t)(k & 0xFFFFu);
    frame->t_mcu_us = k * SM_PERIOD_US; /* unsigned arithmetic wraps at 2^32 like the device clock */
    frame->status = (k % 8u == 7u) ? (uint16_t)(1u << (k % 16u)) : 0;
    for (uint32_t c = 0; c < SM_N_CHIPS; ++c) {
        for (uint32_t a = 0; a < 3; ++a) {
            frame->counts[c][a] = (int16_t)(uint16_t)((k * 97u + c * 1000u + a * 331u) & 0xFFFFu);
        }
        frame->temperature_cdeg[c] = (int16_t)(2500 + 10 * (int)c + (int)(k % 50u));
    }
    frame->has_temperature = with_temperature ? 1 : 0;
}
