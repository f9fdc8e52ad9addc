/* File-backed NVM for the emulator (slipest_nvm_t over a regular file), with the power-loss
 * test hook: the process kills itself with SIGKILL from inside the K-th write or erase: before
 * it touches the file, after only the first half of the sector (a torn write), or right after
 * completing it (before the store sees the result). Writes and erases keep the rules of the strict
 * RAM NVM (firmware_c/common/ram_nvm.h): one whole erased aligned sector, nothing outside the area. */
#ifndef EMU_NVM_H
#define EMU_NVM_H

#include <stdint.h>

#include "slipest_store.h"

typedef struct {
    int fd;
    uint32_t size;       /* bytes of the area */
    uint32_t sector;     /* sector size */
    uint32_t ops;        /* writes + erases so far */
    uint32_t cut_after;  /* 0: never; K: die inside the K-th write/erase */
    int mode;            /* EMU_CUT_BEFORE, EMU_CUT_TORN or EMU_CUT_AFTER */
} emu_nvm_t;

enum { EMU_CUT_BEFORE = 0, EMU_CUT_TORN = 1, EMU_CUT_AFTER = 2 };

/* Open (create, erased to 0xFF, when absent or of another size) path as an area of n_sectors
 * sectors of sector bytes and fill nvm. Returns 0, or -1 with errno set. */
int emu_nvm_open(emu_nvm_t *e, const char *path, uint32_t sector, uint32_t n_sectors, slipest_nvm_t *nvm);

#endif /* EMU_NVM_H */
