/* frame_dump N [--temperature]: write N frames of the firmware's self-test pattern (frame.h) to stdout.
 *
 * The host build of the firmware's own encoder: the Python tests decode these bytes with the driver's
 * decoder and compare them with the documented pattern, so the C encoder and the Python decoder cannot drift
 * apart unnoticed. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "frame.h"

int main(int argc, char **argv)
{
    int with_temperature = 0;
    long n = -1;
    for (int i = 1; i < argc; ++i) {
        if (strcmp(argv[i], "--temperature") == 0) {
            with_temperature = 1;
        } else {
            char *end = NULL;
            n = strtol(argv[i], &end, 10);
            if (end == argv[i] || *end != '\0' || n < 0) {
                fprintf(stderr, "frame_dump: expected a frame count >= 0, got '%s'\n", argv[i]);
                return 2;
            }
        }
    }
    if (n < 0) {
        fprintf(stderr, "usage: frame_dump N [--temperature]\n");
        return 2;
    }
    uint8_t buf[SM_FRAME_LEN_T];
    sm_frame_t frame;
    for (long k = 0; k < n; ++k) {
        sm_self_test_frame((uint32_t)k, with_temperature, &frame);
        size_t len = sm_encode_frame(&frame, buf, sizeof buf);
        if (len == 0 || fwrite(buf, 1, len, stdout) != len) {
            fprintf(stderr, "frame_dump: write failed at frame %ld\n", k);
            return 1;
        }
    }
    return fflush(stdout) == 0 ? 0 : 1;
}
