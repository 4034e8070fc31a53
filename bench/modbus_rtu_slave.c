/* A minimal libmodbus RTU slave: the yardstick bench/rtu_throughput.py holds `servotool sim serve` to on the same
 * serial line. Unit 1, 1000 holding registers from 0x2000 (DSX7E's Pn map), every value 250.
 * Build: gcc -O2 -o modbus_rtu_slave modbus_rtu_slave.c $(pkg-config --cflags --libs libmodbus)  (libmodbus-dev)
 * Run:   modbus_rtu_slave PORT BAUD   (prints "ready" on stdout once the port is open) */
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <modbus.h>

int main(int argc, char **argv) {
    if (argc != 3) {
        fprintf(stderr, "usage: %s PORT BAUD\n", argv[0]);
        return 2;
    }
    modbus_t *ctx = modbus_new_rtu(argv[1], atoi(argv[2]), 'N', 8, 1);
    modbus_mapping_t *map = modbus_mapping_new_start_address(0, 0, 0, 0, 0x2000, 1000, 0, 0);
    if (ctx == NULL || map == NULL || modbus_set_slave(ctx, 1) == -1 || modbus_connect(ctx) == -1) {
        fprintf(stderr, "modbus_rtu_slave: %s\n", modbus_strerror(errno));
        return 1;
    }
    for (int i = 0; i < 1000; i++)
        map->tab_registers[i] = 250;
    printf("ready\n");
    fflush(stdout);
    uint8_t query[MODBUS_RTU_MAX_ADU_LENGTH];
    for (;;) {
        int rc = modbus_receive(ctx, query);
        if (rc > 0)
            modbus_reply(ctx, query, rc, map);
        else if (rc == -1 && errno != EMBBADCRC && errno != ETIMEDOUT && errno != EMBBADDATA)
            break;
    }
    modbus_mapping_free(map);
    modbus_close(ctx);
    modbus_free(ctx);
    return 0;
}
