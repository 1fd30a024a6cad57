import { mkdirSync, readFileSync, renameSync, writeFileSync } from 'node:fs';
import { join } from 'node:path';
import { z } from 'zod';
import type { Logger } from './log';
import { shownUrl, webhookUrlProblem } from './webhook';

/**
 * The server settings a supervisor changes from the console (`settings.json` in the data folder;
 * written atomically). `SHOPDECK_ALARM_WEBHOOK` in the environment overrides the webhook URL (the
 * page then shows it as set by the server's environment and cannot change it).
 */

const settingsSchema = z.object({
  alarmWebhook: z.string().max(2000).nullable().default(null),
});
export type ServerSettings = z.infer<typeof settingsSchema>;

/** What the settings page is shown: never the webhook's path or query (often its secret). */
export interface SettingsView {
  alarmWebhook: { set: boolean; shown: string | null; fromEnvironment: boolean };
}

export class SettingsStore {
  private value: ServerSettings = { alarmWebhook: null };
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

  view(): SettingsView {
    const url = this.webhookUrl();
    return {
      alarmWebhook: {
        set: url !== null,
        shown: url ? shownUrl(url) : null,
        fromEnvironment: Boolean(this.env.SHOPDECK_ALARM_WEBHOOK?.trim()),
      },
    };
  }

  /** Sets the webhook URL (null removes it): an error in words, or null when saved. */
  setWebhook(url: string | null): string | null {
    if (this.env.SHOPDECK_ALARM_WEBHOOK?.trim())
      return 'the webhook URL is set by the server (SHOPDECK_ALARM_WEBHOOK) and cannot be changed here';
    if (url !== null) {
      const problem = webhookUrlProblem(url);
      if (problem) return problem;
    }
    const next = { ...this.value, alarmWebhook: url };
    try {
      mkdirSync(join(this.file, '..'), { recursive: true });
      writeFileSync(`${this.file}.tmp`, JSON.stringify(next, null, 2), { mode: 0o600 });
      renameSync(`${this.file}.tmp`, this.file);
    } catch (e) {
      return `cannot save the settings: ${String(e)}`;
    }
    this.value = next;
    return null;
  }
}
