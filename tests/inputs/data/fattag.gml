<GML spec="0.1b">
  <!-- a phone held sideways, each axis normalised to its own screen side (480 x 320) -->
  <tag>
    <header><client><name>tagbot test (per-axis)</name></client></header>
    <environment>
      <up><x>1</x><y>0</y><z>0</z></up>
      <screenBounds><x>480</x><y>320</y><z>18</z></screenBounds>
    </environment>
    <drawing>
      <stroke>
        <pt><x>0.9</x><y>0.1</y><z>0</z><time>0</time></pt>
        <pt><x>0.1</x><y>0.1</y><z>0</z><time>0.5</time></pt>
        <pt><x>0.1</x><y>0.8</y><z>0</z><time>1</time></pt>
      </stroke>
    </drawing>
  </tag>
</GML>
