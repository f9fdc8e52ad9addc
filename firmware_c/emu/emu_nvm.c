/* File-backed NVM for slipest_emu (emu_nvm.h). pread/pwrite go straight to the kernel, so
 * everything written before a SIGKILL is in the file afterwards, exactly as far as it got. */
#define _XOPEN_SOURCE 700

#include "emu_nvm.h"
#include "ram_nvm.h"

#include <errno.h>
#include <fcntl.h>
#include <signal.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

static int in_area(const emu_nvm_t *e, uint32_t addr, uint32_t len)
{
    return addr <= e->size && len <= e->size - addr;
}

static int put(const emu_nvm_t *e, uint32_t addr, const uint8_t *buf, uint32_t len)
{
    ssize_t w = pwrite(e->fd, buf, len, (off_t)addr);
    return w == (ssize_t)len ? 0 : -1;
}

/* The power-loss hook around every write/erase, which would put len bytes of buf at addr:
 * 1 when the op is the cut one and the caller dies after doing it (mode after). */
static int cut_before(emu_nvm_t *e, uint32_t addr, const uint8_t *buf, uint32_t len)
{
    e->ops++;
    if (e->cut_after == 0u || e->ops != e->cut_after) return 0;
    if (e->mode == EMU_CUT_AFTER) return 1;
    if (e->mode == EMU_CUT_TORN) (void)put(e, addr, buf, len / 2u);
    raise(SIGKILL); /* a real process death: nothing after this point runs */
    return 0;
}

static slipest_status_t put_then_maybe_die(emu_nvm_t *e, int die, uint32_t addr, const uint8_t *buf, uint32_t len)
{
    int r = put(e, addr, buf, len);
    if (die) raise(SIGKILL);
    return r == 0 ? SLIPEST_OK : SLIPEST_E_NVM;
}

static slipest_status_t nvm_read(void *ctx, uint32_t addr, uint8_t *buf, uint32_t len)
{
    emu_nvm_t *e = ctx;
    if (!in_area(e, addr, len)) return SLIPEST_E_RANGE;
    return pread(e->fd, buf, len, (off_t)addr) == (ssize_t)len ? SLIPEST_OK : SLIPEST_E_NVM;
}

static slipest_status_t nvm_write(void *ctx, uint32_t addr, const uint8_t *buf, uint32_t len)
{
    emu_nvm_t *e = ctx;
    uint8_t cur[SLIPEST_STORE_SECTOR_MAX];
    slipest_status_t st = ram_nvm_erase_rule(addr, e->sector, e->size); /* aligned and inside: cur can be read */
    if (st != SLIPEST_OK) return st;
    if (pread(e->fd, cur, e->sector, (off_t)addr) != (ssize_t)e->sector) return SLIPEST_E_NVM;
    st = ram_nvm_write_rule(addr, len, e->sector, e->size, cur); /* the strict NVM's rules, on the file */
    if (st != SLIPEST_OK) return st;
    return put_then_maybe_die(e, cut_before(e, addr, buf, len), addr, buf, len);
}

static slipest_status_t nvm_erase(void *ctx, uint32_t addr)
{
    emu_nvm_t *e = ctx;
    uint8_t ff[SLIPEST_STORE_SECTOR_MAX];
    if (ram_nvm_erase_rule(addr, e->sector, e->size) != SLIPEST_OK) return SLIPEST_E_RANGE;
    memset(ff, 0xFF, e->sector);
    return put_then_maybe_die(e, cut_before(e, addr, ff, e->sector), addr, ff, e->sector);
}

int emu_nvm_open(emu_nvm_t *e, const char *path, uint32_t sector, uint32_t n_sectors, slipest_nvm_t *nvm)
{
    struct stat st;
    uint32_t i;
    uint8_t ff[SLIPEST_STORE_SECTOR_MAX];
    if (sector == 0u || sector > SLIPEST_STORE_SECTOR_MAX) {
        errno = EINVAL;
        return -1;
    }
    e->fd = open(path, O_RDWR | O_CREAT, 0644);
    if (e->fd < 0 || fstat(e->fd, &st) != 0) return -1;
    e->size = sector * n_sectors;
    e->sector = sector;
    e->ops = 0u;
    if ((uint64_t)st.st_size != (uint64_t)e->size) { /* new (or another geometry): all erased */
        memset(ff, 0xFF, sector);
        if (ftruncate(e->fd, 0) != 0) return -1;
        for (i = 0; i < n_sectors; ++i) {
            if (put(e, i * sector, ff, sector) != 0) return -1;
        }
    }
    nvm->read = nvm_read;
    nvm->write = nvm_write;
    nvm->erase = nvm_erase;
    nvm->sector_size = sector;
    nvm->n_sectors = n_sectors;
    nvm->ctx = e;
    return 0;
}
