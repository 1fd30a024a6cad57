import { closeSync, fsyncSync, mkdirSync, openSync, readFileSync, renameSync, writeSync } from 'node:fs';
import { join } from 'node:path';
import { z } from 'zod';
import type { Logger } from './log';
import { shownUrl, webhookUrlProblem } from './webhook';

/**
 * The server settings a supervisor changes from the console (`settings.json` in the data folder;
 * written atomically). `SHOPDECK_ALARM_WEBHOOK` in the environment overrides the webhook URL (the
 * page then shows it as set by the server's environment and cannot change it).
 */

/** `HH:MM`, 00:00 to 23:59 (the server's local time). */
const clock = z.string().regex(/^([01]\d|2[0-3]):[0-5]\d$/, 'a time of day as HH:MM (00:00 to 23:59)');

export const shiftSchema = z
  .object({
    name: z.string().trim().min(1, 'a shift needs a name').max(40),
    start: clock,
    /** Not after `start`: the shift ends the next day (a night shift); equal to `start`: 24 hours. */
    end: clock,
  })
  .strict();
export type Shift = z.infer<typeof shiftSchema>;

export const shiftsSchema = z
  .array(shiftSchema)
  .max(12, 'at most 12 shifts')
  .refine((l) => new Set(l.map((s) => s.name.toLowerCase())).size === l.length, 'shift names must differ');

export const retentionSchema = z
  .object({
    /** Jobs (and TouchCut's daily statistics) older than this many days are pruned. */
    jobsDays: z.number().int().min(1).max(3650),
    /** State changes (the timeline, utilisation, stop reasons) older than this are pruned. */
    statesDays: z.number().int().min(1).max(3650),
  })
  .strict();
export type Retention = z.infer<typeof retentionSchema>;

export const DEFAULT_SHIFTS: Shift[] = [
  { name: 'Early', start: '06:00', end: '14:00' },
  { name: 'Late', start: '14:00', end: '22:00' },
  { name: 'Night', start: '22:00', end: '06:00' },
];
export const DEFAULT_RETENTION: Retention = { jobsDays: 365, statesDays: 90 };

const settingsSchema = z.object({
  alarmWebhook: z.string().max(2000).nullable().default(null),
  /**
   * Hosts the alarm webhook may reach although they are refused otherwise (this computer,
   * link-local, a machine of the machines file): `host` or `host:port`. Only in the file on the
   * server (a person with the server's shell), never from the page (`PUT /api/settings`).
   */
  webhookAllowHosts: z.array(z.string().trim().min(1).max(300)).max(50).default([]),
  shifts: shiftsSchema.default(DEFAULT_SHIFTS),
  retention: retentionSchema.default(DEFAULT_RETENTION),
});
export type ServerSettings = z.infer<typeof settingsSchema>;

/** What the settings page is shown: never the webhook's path or query (often its secret). */
export interface SettingsView {
  alarmWebhook: { set: boolean; shown: string | null; fromEnvironment: boolean };
  shifts: Shift[];
  retention: Retention;
}

export class SettingsStore {
  private value: ServerSettings = {
    alarmWebhook: null,
    webhookAllowHosts: [],
    shifts: DEFAULT_SHIFTS,
    retention: DEFAULT_RETENTION,
  };
  private readonly file: string;

  constructor(
    dataDir: string,
    private readonly env: NodeJS.ProcessEnv,
    private readonly log: Logger,
  ) {
    this.file = join(dataDir, 'settings.json');
    this.load();
  }

  private load(): void {
    let text: string;
    try {
      text = readFileSync(this.file, 'utf8');
    } catch {
      return;
    }
    try {
      const r = settingsSchema.safeParse(JSON.parse(text));
      if (r.success) {
        this.value = r.data;
        return;
      }
    } catch {
      /* below */
    }
    this.log.error(
      'the server settings file cannot be read; the defaults are used until a supervisor saves',
      {
        file: this.file,
      },
    );
  }

  /** The webhook URL in force (the environment's first). */
  webhookUrl(): string | null {
    const fromEnv = this.env.SHOPDECK_ALARM_WEBHOOK?.trim();
    if (fromEnv) return webhookUrlProblem(fromEnv) ? null : fromEnv;
    return this.value.alarmWebhook;
  }

  /** Hosts the settings file allows the webhook to reach although they would be refused. */
  webhookAllowHosts(): readonly string[] {
    return this.value.webhookAllowHosts;
  }

  view(): SettingsView {
    const url = this.webhookUrl();
    return {
      alarmWebhook: {
        set: url !== null,
        shown: url ? shownUrl(url) : null,
        fromEnvironment: Boolean(this.env.SHOPDECK_ALARM_WEBHOOK?.trim()),
      },
      shifts: this.value.shifts,
      retention: this.value.retention,
    };
  }

  /** The shifts of the shift report (the server's local time). */
  shifts(): Shift[] {
    return this.value.shifts;
  }

  retention(): Retention {
    return this.value.retention;
  }

  /** Sets the shifts and/or the retention (validated by the caller): an error in words, or null. */
  setHistory(change: { shifts?: Shift[]; retention?: Retention }): string | null {
    return this.save({
      ...this.value,
      ...(change.shifts ? { shifts: change.shifts } : {}),
      ...(change.retention ? { retention: change.retention } : {}),
    });
  }

  /** Sets the webhook URL (null removes it): an error in words, or null when saved. */
  setWebhook(url: string | null): string | null {
    if (this.env.SHOPDECK_ALARM_WEBHOOK?.trim())
      return 'the webhook URL is set by the server (SHOPDECK_ALARM_WEBHOOK) and cannot be changed here';
    if (url !== null) {
      const problem = webhookUrlProblem(url);
      if (problem) return problem;
    }
    return this.save({ ...this.value, alarmWebhook: url });
  }

  private save(next: ServerSettings): string | null {
    try {
      mkdirSync(join(this.file, '..'), { recursive: true });
      // On disk (fsynced) before the change is answered and audited.
      const fd = openSync(`${this.file}.tmp`, 'w', 0o600);
      try {
        writeSync(fd, JSON.stringify(next, null, 2));
        fsyncSync(fd);
      } finally {
        closeSync(fd);
      }
      renameSync(`${this.file}.tmp`, this.file);
    } catch (e) {
      return `cannot save the settings: ${String(e)}`;
    }
    this.value = next;
    return null;
  }
}
