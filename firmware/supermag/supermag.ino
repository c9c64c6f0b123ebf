/* SuperMag reference firmware: ESP32 + 16 MLX90393 on one SPI bus, streaming the wire protocol of docs/design.md at 125 Hz.
 *
 * Bus: VSPI (SCK 18, MISO 19, MOSI 23), mode 3, 4 MHz. Chip selects come from a 74HC154 4-to-16 decoder:
 * address lines A0..A3 on GPIO 25, 26, 27, 32 pick chip i (row-major over the 4x4 grid), and GPIO 33 drives
 * the decoder's active-low enables, so exactly one CS is low while GPIO 33 is low and none otherwise.
 * (Why SPI and a decoder, the wiring and the bring-up checklist: README.md.)
 *
 * Chip settings (register 0x00 / 0x02, the ReSkin/AnySkin values): HALLCONF 0xC, GAIN_SEL 6, RES_XYZ 0,
 * OSR 0, DIG_FILT 2 -> 0.200 uT/LSB (x, y) and 0.323 uT/LSB (z), the host's ChipParams. Each chip runs in
 * burst mode (SB with zyxt = 0xF, BURST_DATA_RATE 0: back-to-back conversions of about
 * 3 * (67 + 64 * 2^OSR * (2 + 2^DIG_FILT)) + (67 + 192 * 2^OSR2) = 1612 us), and every 8 ms the firmware
 * reads the newest result of each chip with RM (0x4F: status byte, then T, X, Y, Z, MSB first).
 *
 * Status bits: bit i is set in a frame when chip i answered with its ERROR bit, had left burst mode, or
 * returned an all-ones status (no chip on the line); its counts are 0 in that frame and the chip is put back
 * into burst mode. Build with -DSM_SELF_TEST=1 to stream the documented test pattern without any chip
 * (frame.h), the first bring-up step.
 */
#include <Arduino.h>
#include <SPI.h>

#include "frame.h"

#ifndef SM_SELF_TEST
#define SM_SELF_TEST 0
#endif
#ifndef SM_SEND_TEMPERATURE
#define SM_SEND_TEMPERATURE 1
#endif

static const uint32_t BAUD = 921600;
static const uint32_t SPI_HZ = 4000000; // the MLX90393 allows up to 10 MHz; 4 MHz keeps long ribbon cables safe
static const int PIN_SCK = 18, PIN_MISO = 19, PIN_MOSI = 23;
static const int PIN_ADDR[4] = {25, 26, 27, 32}; // 74HC154 A0..A3
static const int PIN_ENABLE = 33;                // 74HC154 /E1 and /E2 tied together, active low

// MLX90393 commands (datasheet section "Command List"): the low nibble of SB/SM/RM selects zyxt.
static const uint8_t CMD_SB = 0x10, CMD_RM = 0x40, CMD_RR = 0x50, CMD_WR = 0x60, CMD_EX = 0x80, CMD_RT = 0xF0;
static const uint8_t ZYXT_ALL = 0x0F;
static const uint8_t ST_BURST = 0x80, ST_ERROR = 0x10;
static const uint8_t REG_CONF0 = 0x00, REG_CONF1 = 0x01, REG_CONF2 = 0x02, REG_TREF = 0x24;

// Register values: see the file comment. CONF1: COMM_MODE = 0b10 (SPI only), BURST_DATA_RATE 0, BURST_SEL 0.
static const uint16_t CONF0 = (6u << 4) | 0x0Cu;           // GAIN_SEL 6, HALLCONF 0xC
static const uint16_t CONF1 = (2u << 13);                  // SPI only
static const uint16_t CONF2 = (0u << 5) | (2u << 2) | 0u;  // RES_XYZ 0, DIG_FILT 2, OSR 0
static const float TEMP_LSB_PER_C = 45.2f;                 // datasheet: 45.2 LSB/degC around TREF at 25 degC

static SPISettings spi_settings(SPI_HZ, MSBFIRST, SPI_MODE3);
static sm_frame_t frame;
static uint8_t wire[SM_FRAME_LEN_T];
static uint32_t next_us;

#if !SM_SELF_TEST // the chip driver; the self-test build streams the pattern without touching the bus
static uint16_t tref[SM_N_CHIPS]; // TREF register of each chip (temperature at 25 degC)

static void select_chip(int chip)
{
    for (int b = 0; b < 4; ++b) {
        digitalWrite(PIN_ADDR[b], (chip >> b) & 1);
    }
    digitalWrite(PIN_ENABLE, LOW);
}

static void deselect(void) { digitalWrite(PIN_ENABLE, HIGH); }

// One command: send n_tx bytes, then clock in n_rx answer bytes (the status byte first). Returns the status.
static uint8_t command(int chip, const uint8_t *tx, int n_tx, uint8_t *rx, int n_rx)
{
    SPI.beginTransaction(spi_settings);
    select_chip(chip);
    for (int i = 0; i < n_tx; ++i) {
        SPI.transfer(tx[i]);
    }
    for (int i = 0; i < n_rx; ++i) {
        rx[i] = SPI.transfer(0x00);
    }
    deselect();
    SPI.endTransaction();
    return n_rx > 0 ? rx[0] : 0;
}

static uint8_t simple(int chip, uint8_t cmd)
{
    uint8_t st;
    return command(chip, &cmd, 1, &st, 1);
}

static uint8_t write_register(int chip, uint8_t reg, uint16_t value)
{
    const uint8_t tx[4] = {CMD_WR, (uint8_t)(value >> 8), (uint8_t)(value & 0xFF), (uint8_t)(reg << 2)};
    uint8_t st;
    return command(chip, tx, 4, &st, 1);
}

static uint16_t read_register(int chip, uint8_t reg, uint8_t *status)
{
    const uint8_t tx[2] = {CMD_RR, (uint8_t)(reg << 2)};
    uint8_t rx[3];
    *status = command(chip, tx, 2, rx, 3);
    return (uint16_t)((rx[1] << 8) | rx[2]);
}

static bool chip_failed(uint8_t status) { return status == 0xFF || (status & ST_ERROR); }

// Exit any mode, reset, write the settings, read TREF and start burst mode; true when every answer was good.
static bool start_chip(int chip)
{
    simple(chip, CMD_EX);
    delay(1);
    simple(chip, CMD_RT);
    delay(2); // power-on/reset time of the MLX90393 is below 2 ms
    bool ok = !chip_failed(write_register(chip, REG_CONF0, CONF0));
    ok = !chip_failed(write_register(chip, REG_CONF1, CONF1)) && ok;
    ok = !chip_failed(write_register(chip, REG_CONF2, CONF2)) && ok;
    uint8_t st;
    tref[chip] = read_register(chip, REG_TREF, &st);
    ok = !chip_failed(st) && ok;
    ok = !chip_failed(simple(chip, CMD_SB | ZYXT_ALL)) && ok;
    return ok;
}

// RM of one chip into the frame; returns false (and zeroes its counts) when the chip failed.
static bool read_chip(int chip)
{
    const uint8_t tx = CMD_RM | ZYXT_ALL;
    uint8_t rx[9]; // status, T, X, Y, Z (MSB first)
    uint8_t st = command(chip, &tx, 1, rx, 9);
    if (chip_failed(st) || !(st & ST_BURST)) {
        frame.counts[chip][0] = frame.counts[chip][1] = frame.counts[chip][2] = 0;
        frame.temperature_cdeg[chip] = 0;
        return false;
    }
    uint16_t t_raw = (uint16_t)((rx[1] << 8) | rx[2]);
    for (int a = 0; a < 3; ++a) {
        // RES 0: the output register is a signed 16-bit value
        frame.counts[chip][a] = (int16_t)(uint16_t)((rx[3 + 2 * a] << 8) | rx[4 + 2 * a]);
    }
    float t_c = 25.0f + ((float)t_raw - (float)tref[chip]) / TEMP_LSB_PER_C;
    frame.temperature_cdeg[chip] = (int16_t)lroundf(t_c * 100.0f);
    return true;
}

#endif // !SM_SELF_TEST

void setup()
{
    Serial.setTxBufferSize(1024); // two frames: a slow host read never blocks the 8 ms loop for long
    Serial.begin(BAUD);
    pinMode(PIN_ENABLE, OUTPUT);
    digitalWrite(PIN_ENABLE, HIGH); // no chip selected
    for (int b = 0; b < 4; ++b) {
        pinMode(PIN_ADDR[b], OUTPUT);
    }
    SPI.begin(PIN_SCK, PIN_MISO, PIN_MOSI, -1);
#if !SM_SELF_TEST
    for (int chip = 0; chip < SM_N_CHIPS; ++chip) {
        start_chip(chip); // a chip that fails here shows up in the status bits of every frame
    }
#endif
    next_us = micros();
}

void loop()
{
    static uint32_t k = 0;
    while ((int32_t)(micros() - next_us) < 0) {
        // wait for the next 8 ms tick (a signed difference survives the 2^32 wrap of micros())
    }
    next_us += SM_PERIOD_US;
#if SM_SELF_TEST
    sm_self_test_frame(k, SM_SEND_TEMPERATURE, &frame);
#else
    frame.seq = (uint16_t)k;
    frame.t_mcu_us = micros();
    frame.status = 0;
    frame.has_temperature = SM_SEND_TEMPERATURE;
    for (int chip = 0; chip < SM_N_CHIPS; ++chip) {
        if (!read_chip(chip)) {
            frame.status |= (uint16_t)(1u << chip);
            start_chip(chip); // back into burst mode; its next frame tells whether that worked
        }
    }
#endif
    size_t len = sm_encode_frame(&frame, wire, sizeof wire);
    Serial.write(wire, len);
    ++k;
}
