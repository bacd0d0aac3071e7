<gml spec="1.0">
  <tag>
    <drawing>
      <stroke>
        <pt><x>0.1</x><y>0.1</y><t>1262304000000</t></pt>
        <pt><x>0.2</x><y>0.1</y><t>1262304000016</t></pt>
        <pt><x>0.3</x><y>0.1</y><t>1262304000033</t></pt>
      </stroke>
      <stroke>
        <pt><x>0.1</x><y>0.5</y><t>1262304001000</t></pt>
        <pt><x>0.2</x><y>0.5</y><t>1262304001500</t></pt>
      </stroke>
    </drawing>
  </tag>
</gml>
